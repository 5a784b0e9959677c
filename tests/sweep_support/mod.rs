//! Running `sandstep sweep` from a test: the sweep file written from text into a temporary
//! folder, the report read from `--json`. Shared by the sweep, sand-window and bed tests.
#![allow(dead_code)]

use std::path::PathBuf;
use std::process::Command;

use serde_json::Value;

/// A finished sweep: its report (`results.json`) and where it wrote its outputs.
pub struct SweepRun {
    pub report: Value,
    /// The `--out` folder (results.csv, charts); it lives as long as `_dir`.
    pub out: PathBuf,
    _dir: tempfile::TempDir,
}

impl SweepRun {
    /// The result rows, in run order.
    pub fn results(&self) -> &[Value] {
        self.report["results"].as_array().expect("results")
    }

    /// The row of `setting` in `study`.
    pub fn row(&self, study: &str, setting: &str) -> &Value {
        self.results()
            .iter()
            .find(|r| r["study"] == study && r["setting"] == setting)
            .unwrap_or_else(|| panic!("no row {study}/{setting}"))
    }
}

/// Runs `sandstep sweep` on the sweep file `text` (relative paths from the crate's root) and
/// returns its report; panics with stderr if the command fails.
pub fn run_sweep(text: &str) -> SweepRun {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("sweep.yaml");
    std::fs::write(&file, text).unwrap();
    let out = dir.path().join("out");
    let output = Command::new(env!("CARGO_BIN_EXE_sandstep"))
        .arg("sweep")
        .arg(&file)
        .arg("--out")
        .arg(&out)
        .arg("--json")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stderr}");
    SweepRun {
        report: serde_json::from_slice(&output.stdout).unwrap(),
        out,
        _dir: dir,
    }
}

/// The number `key` of a result row; panics naming the row if it is missing.
pub fn num(row: &Value, key: &str) -> f64 {
    row[key]
        .as_f64()
        .unwrap_or_else(|| panic!("{key} in {row}"))
}
