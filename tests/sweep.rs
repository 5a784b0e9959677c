//! `sandstep sweep` end to end, through the command line, on a small sweep (seconds): the
//! column collapse on coarse grids in a wider channel, and the robot on resistive force theory
//! against its quarter-millisecond run. Pins what the sweep measures (coarser grids cost less
//! and miss the published runout by more), what it writes (the documented CSV columns, a chart
//! per study), that the Pareto front is the set no other setting beats on both cost and error,
//! and that a setting that blows up is recorded while the others go on.

use std::process::Command;

use serde_json::Value;

mod sweep_support;
use sweep_support::{num, run_sweep};

/// The columns `docs/speed-vs-accuracy.md` documents for `results.csv`.
const CSV_COLUMNS: [&str; 17] = [
    "study",
    "setting",
    "quantity",
    "value",
    "value_std",
    "starts",
    "reference_value",
    "relative_error",
    "relative_error_noise",
    "wall_time_per_sim_s",
    "wall_time_s",
    "sim_time_s",
    "particles",
    "substeps",
    "pareto_optimal",
    "status",
    "overrides",
];

/// Lube et al. 2005: normalized runout 1.2 a below a = 1.8, here a = 1.
const LUBE_RUNOUT_AT_A1: f64 = 1.2;
/// The quarter-millisecond RFT reference and the auto step walk within 6 % of each other
/// (tests/rft.rs); on poppy seeds the auto step is 8 ms.
const RFT_STEP_ERROR: f64 = 0.06;

const SWEEP: &str = r#"
name: small
studies:
  - name: collapse
    base_scene: config/column_collapse.yaml
    # A 16 mm channel takes 2 cells of 8 mm; 0.5 s covers the collapse at a = 1.
    overrides: ["sand.domain.max_m=[0.4, 0.016, 0.2]", sand.dx_m=0.006, duration_s=0.5]
    quantity: collapse_runout
    vary:
      - key: sand.dx_m
        values: [0.008]
    settings:
      - name: beyond_cfl
        overrides: [sand.solver.fixed_dt_s=0.01]
  - name: robot_rft
    base_scene: config/robot_on_sand.yaml
    overrides: [terrain.model=rft, terrain.rft.zeta_n_m3=3.0e5]
    quantity: robot_speed
    reference: [terrain.rft.max_dt_s=0.00025]
    cycles: 1
    starts: 2
    vary:
      - key: terrain.rft.max_dt_s
        values: [0.001, 0.004]
"#;

#[test]
fn sweep_measures_cost_and_error_marks_the_pareto_front_and_records_failures() {
    let sweep = run_sweep(SWEEP);
    let (report, out) = (&sweep.report, &sweep.out);
    let results = sweep.results();
    let row = |study: &str, setting: &str| sweep.row(study, setting);
    assert_eq!(results.len(), 7, "{results:#?}");
    assert_eq!(report["failed"], 1);

    // The collapse converges towards the law as the grid is refined, at a price.
    let fine = row("collapse", "baseline");
    let coarse = row("collapse", "dx_m=0.008");
    let f = num;
    for r in [fine, coarse] {
        assert_eq!(r["status"], "ok", "{r}");
        // The aspect ratio is an f32 in the scene.
        assert!(
            (f(r, "reference_value") - LUBE_RUNOUT_AT_A1).abs() < 1e-6,
            "{r}"
        );
        let law = f(r, "reference_value");
        let expected = (f(r, "value") - law).abs() / law;
        assert!((f(r, "relative_error") - expected).abs() < 1e-12, "{r}");
    }
    assert!(
        f(fine, "relative_error") < f(coarse, "relative_error") - 0.02,
        "6 mm {fine}\n8 mm {coarse}"
    );
    // The price in work, not wall time (which tests never compare): particle-substeps.
    let work = |r: &Value| f(r, "particles") * f(r, "substeps");
    assert!(f(fine, "particles") > f(coarse, "particles"));
    assert!(work(fine) > work(coarse), "6 mm {fine}\n8 mm {coarse}");
    // A fixed step far beyond the CFL limit blows up: recorded, and the sweep went on.
    let blown = row("collapse", "beyond_cfl");
    let status = blown["status"].as_str().unwrap();
    assert!(status.contains("blew up"), "{status}");
    assert!(blown["relative_error"].is_null() && blown["pareto_optimal"] == false);

    // RFT: errors against the reference run, which has none.
    let reference = row("robot_rft", "reference");
    assert_eq!(f(reference, "relative_error"), 0.0);
    assert_eq!(
        reference["pareto_optimal"], false,
        "the reference is not a candidate"
    );
    let reference_speed = f(reference, "value");
    assert!(
        reference_speed > 0.05,
        "the robot walks forward: {reference}"
    );
    for setting in ["baseline", "max_dt_s=0.001", "max_dt_s=0.004"] {
        let r = row("robot_rft", setting);
        assert_eq!(f(r, "reference_value"), reference_speed);
        assert!(f(r, "relative_error") < RFT_STEP_ERROR, "{r}");
        // Two starts, 2 mm apart: the value is their mean, with a spread and a noise.
        assert_eq!(r["starts"], 2, "{r}");
        assert!(
            f(r, "value_std") >= 0.0 && f(r, "relative_error_noise") >= 0.0,
            "{r}"
        );
        // results.json keeps each start's value: the value is their mean.
        let starts: Vec<f64> = r["start_values"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert_eq!(starts.len(), 2, "{r}");
        assert!(
            (starts.iter().sum::<f64>() / 2.0 - f(r, "value")).abs() < 1e-12,
            "{r}"
        );
        let duration = f(reference, "sim_time_s") / 2.0;
        assert!((f(r, "sim_time_s") - 2.0 * duration).abs() < 1e-6, "{r}");
    }
    // The noise of an error combines both spreads: sqrt(se_r^2 + se_s^2) / reference.
    let r = row("robot_rft", "max_dt_s=0.004");
    let se = |v: &Value| f(v, "value_std") / 2f64.sqrt();
    let noise = (se(r).powi(2) + se(reference).powi(2)).sqrt() / reference_speed;
    assert!((f(r, "relative_error_noise") - noise).abs() < 1e-12, "{r}");
    assert!(reference["relative_error_noise"].is_null());
    // The collapse is run once per setting.
    assert_eq!(fine["starts"], 1);
    assert!(fine["value_std"].is_null() && fine["relative_error_noise"].is_null());

    // The front: no optimal setting is beaten on both; every other ok setting is.
    for study in ["collapse", "robot_rft"] {
        let candidates: Vec<&Value> = results
            .iter()
            .filter(|r| r["study"] == study && r["status"] == "ok" && r["setting"] != "reference")
            .collect();
        let beats = |a: &Value, b: &Value| {
            let (ca, ea, cb, eb) = (
                f(a, "wall_time_per_sim_s"),
                f(a, "relative_error"),
                f(b, "wall_time_per_sim_s"),
                f(b, "relative_error"),
            );
            ca <= cb && ea <= eb && (ca < cb || ea < eb)
        };
        assert!(candidates.iter().any(|r| r["pareto_optimal"] == true));
        for r in &candidates {
            let beaten = candidates.iter().any(|q| beats(q, r));
            assert_eq!(r["pareto_optimal"] == true, !beaten, "{study}: {r}");
        }
    }

    // results.csv has the documented columns and a row per setting; a chart per study.
    let csv = std::fs::read_to_string(out.join("results.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(lines.next().unwrap(), CSV_COLUMNS.join(","));
    assert_eq!(lines.count(), results.len());
    for study in ["collapse", "robot_rft"] {
        let png = std::fs::read(out.join(format!("{study}.png"))).unwrap();
        assert!(png.starts_with(b"\x89PNG"));
        let svg = std::fs::read_to_string(out.join(format!("{study}.svg"))).unwrap();
        assert!(svg.contains("Pareto front"), "{svg:.300}");
    }
    // The collapse study's runouts beside the law: its two measured points, the robot's none.
    let law_svg = std::fs::read_to_string(out.join("collapse_law.svg")).unwrap();
    assert!(law_svg.contains("Lube et al. 2005"), "{law_svg:.300}");
    for setting in ["baseline", "dx_m=0.008"] {
        assert!(law_svg.contains(setting), "{setting} not labelled");
    }
    assert!(!out.join("robot_rft_law.svg").exists());
}

#[test]
fn bad_sweep_files_fail_before_running_and_name_the_field() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("bad.yaml");
    std::fs::write(
        &file,
        "name: bad\nstudies:\n  - name: c\n    base_scene: config/column_collapse.yaml\n    quantity: collapse_runout\n    vary:\n      - key: sand.solver.cfl\n        values: [1.5]\n",
    )
    .unwrap();
    let output = Command::new(env!("CARGO_BIN_EXE_sandstep"))
        .args(["sweep", file.to_str().unwrap(), "--out"])
        .arg(dir.path().join("out"))
        .output()
        .unwrap();
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("bad.yaml")
            && stderr.contains("studies.0.vary.0.values.0")
            && stderr.contains("cfl"),
        "{stderr}"
    );
    assert!(
        !dir.path().join("out").exists(),
        "nothing is written for a bad file"
    );
    let unknown = Command::new(env!("CARGO_BIN_EXE_sandstep"))
        .args(["sweep", "config/sweeps/accuracy.yaml", "--study", "nope"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&unknown.stderr);
    assert!(
        !unknown.status.success() && stderr.contains("nope"),
        "{stderr}"
    );
}
