//! The bed rule (`src/scene/bed.rs`, `docs/scenes.md` "How big a bed"): the shipped bed of
//! `config/robot_on_sand.yaml` is the rule's least bed, so more sand must not change the robot's
//! speed. Measured by `sandstep sweep`: the hexapod with C-legs at 2 Hz (dx = 1.25 cm, sleeping
//! sand on so that the extra sand costs little), 1 gait cycle after 0.5 s, from two starts 2 mm
//! apart, on the shipped bed and on one twice as deep, 8 cm wider either side and 8 cm longer
//! behind. About 3 minutes on 2 cores.

use std::process::Command;

use serde_json::Value;

/// The run-to-run spread of the speed is large (`docs/speed-vs-accuracy.md`); a change counts
/// when it exceeds this many standard errors...
const NOISE_MULTIPLE: f64 = 2.5;
/// ...plus this relative allowance.
const SPEED_TOLERANCE: f64 = 0.05;

const SWEEP: &str = r#"
name: bed
studies:
  - name: bed
    base_scene: config/robot_on_sand.yaml
    overrides: [sand.dx_m=0.0125, "sand.solver.sleep={}"]
    quantity: robot_speed
    # Deeper (6 cm instead of 3), wider (+-20 cm instead of +-12) and longer behind (from
    # -20 cm instead of -12).
    reference:
      - "sand.domain.min_m=[-0.2, -0.2, -0.06]"
      - "sand.domain.max_m=[0.8, 0.2, 0.06]"
      - "sand.bodies.0.box.min_m=[-0.2, -0.2, -0.06]"
      - "sand.bodies.0.box.max_m=[0.8, 0.2, 0.0]"
      - robot.ground.height_m=-0.06
    settle_s: 0.5
    cycles: 1
    starts: 2
"#;

#[test]
fn robot_walks_as_fast_on_the_rules_bed_as_on_a_larger_one() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("bed.yaml");
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
    let [larger, shipped] = [0, 1].map(|i| &results[i]);
    assert_eq!(larger["setting"], "reference");
    let f = |v: &Value, key: &str| v[key].as_f64().unwrap_or_else(|| panic!("{key} in {v}"));
    eprintln!(
        "larger bed {:.4} +- {:.4} m/s ({} particles); shipped bed {:.4} +- {:.4} m/s ({} \
         particles): change {:.1} +- {:.1} %",
        f(larger, "value"),
        f(larger, "value_std"),
        larger["particles"],
        f(shipped, "value"),
        f(shipped, "value_std"),
        shipped["particles"],
        100.0 * f(shipped, "relative_error"),
        100.0 * f(shipped, "relative_error_noise"),
    );
    assert!(f(larger, "value") > 0.05, "the robot walks: {larger}");
    assert!(f(larger, "particles") > 3.0 * f(shipped, "particles"));
    let bound = NOISE_MULTIPLE * f(shipped, "relative_error_noise") + SPEED_TOLERANCE;
    assert!(
        f(shipped, "relative_error") < bound,
        "more sand changes the speed by more than {:.0} %: {shipped}",
        100.0 * bound
    );
}
