//! Shared by integration tests that check the crate's output with Python tools (`mcap`,
//! `rosbags`, `cyclonedds`): the virtual environment of `tests/python/requirements.txt`.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

/// The crate's root directory.
fn crate_dir() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The Python interpreter of `target/py-venv`, set up (once per test binary) by
/// `tests/python/setup_venv.sh`. Panics with the script's output if that fails: tests that need
/// Python fail, never skip.
pub fn python() -> PathBuf {
    static PYTHON: OnceLock<PathBuf> = OnceLock::new();
    PYTHON
        .get_or_init(|| {
            let script = crate_dir().join("tests/python/setup_venv.sh");
            let output = Command::new("bash")
                .arg(&script)
                .output()
                .unwrap_or_else(|e| panic!("cannot run {}: {e}", script.display()));
            let stdout = String::from_utf8_lossy(&output.stdout);
            let stderr = String::from_utf8_lossy(&output.stderr);
            assert!(
                output.status.success(),
                "{} failed ({}):\n{stdout}\n{stderr}",
                script.display(),
                output.status
            );
            let python = PathBuf::from(stdout.lines().last().unwrap_or_default().trim());
            assert!(
                python.is_file(),
                "{} did not print the venv's python (got {python:?}):\n{stdout}\n{stderr}",
                script.display()
            );
            python
        })
        .clone()
}

/// Runs `tests/python/<script>` with `args` in the venv and parses the JSON line it prints
/// last. Panics with its output if it fails or prints no JSON.
#[allow(dead_code)] // not every test binary that includes this module runs scripts
pub fn run_python_json(script: &str, args: &[&Path]) -> serde_json::Value {
    let path = crate_dir().join("tests/python").join(script);
    let output = Command::new(python())
        .arg(&path)
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("cannot run {}: {e}", path.display()));
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        output.status.success(),
        "{script} failed ({}):\n{stderr}\n{stdout}",
        output.status
    );
    let last = stdout.lines().last().unwrap_or_default();
    serde_json::from_str(last)
        .unwrap_or_else(|e| panic!("{script} printed no JSON line ({e}):\n{stdout}\n{stderr}"))
}
