//! The sand window (`sand.window`) against the whole bed, measured by `sandstep sweep`: the
//! hexapod with C-legs at 2 Hz on `config/robot_on_sand.yaml`'s 92 cm bed (dx = 1.25 cm, the
//! experiment test's grid), 2 gait cycles after 0.5 s of settling. With the window only the
//! sand from 10 cm behind the body to 20 cm ahead is simulated; the robot must walk as fast as
//! on the whole bed (within the run-to-run spread of the speed, docs/speed-vs-accuracy.md)
//! while the window moves along and holds a fraction of the bed's particles. About 4 minutes
//! on 2 cores.

use std::process::Command;

use serde_json::Value;

/// Largest relative change of the robot's mean speed the window may cause.
const SPEED_TOLERANCE: f64 = 0.08;

const SWEEP: &str = r#"
name: window
studies:
  - name: window
    base_scene: config/robot_on_sand.yaml
    overrides: [sand.dx_m=0.0125]
    quantity: robot_speed
    reference: []
    baseline: false
    settings:
      - name: window
        overrides: ["sand.window={behind_m: 0.1, ahead_m: 0.2, step_m: 0.05}"]
"#;

#[test]
fn robot_walks_as_fast_in_the_sand_window_as_on_the_whole_bed() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("window.yaml");
    std::fs::write(&file, SWEEP).unwrap();
    let output = Command::new(env!("CARGO_BIN_EXE_sandstep"))
        .args(["sweep", file.to_str().unwrap(), "--json", "--out"])
        .arg(dir.path().join("out"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stderr}");
    let report: Value = serde_json::from_slice(&output.stdout).unwrap();
    let results = report["results"].as_array().unwrap();
    assert_eq!(report["failed"], 0, "{results:#?}");
    let [whole, window] = [0, 1].map(|i| &results[i]);
    assert_eq!(whole["setting"], "reference");
    let f = |v: &Value, key: &str| v[key].as_f64().unwrap_or_else(|| panic!("{key} in {v}"));
    let speed = f(whole, "value");
    assert!(
        speed > 0.05,
        "the robot walks forward on the whole bed: {whole}"
    );
    eprintln!(
        "whole bed {speed:.4} m/s, {} particles, {:.1} s/s; window {:.4} m/s, {} particles at the end, {:.1} s/s",
        whole["particles"],
        f(whole, "wall_time_per_sim_s"),
        f(window, "value"),
        window["particles"],
        f(window, "wall_time_per_sim_s")
    );
    assert!(
        f(window, "relative_error") < SPEED_TOLERANCE,
        "the window changes the speed: {window}"
    );
    // The window moved with the robot (filled ahead, dropped behind) and at the end holds well
    // under half the bed.
    let metrics = &window["metrics"];
    assert!(
        metrics["sand_added"].as_u64().unwrap() > 0
            && metrics["sand_dropped"].as_u64().unwrap() > 0,
        "{metrics}"
    );
    assert!(
        f(window, "particles") < 0.5 * f(whole, "particles"),
        "{window}\n{whole}"
    );
}
