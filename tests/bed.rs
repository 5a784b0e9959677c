//! The bed rule (`src/scene/bed.rs`, `docs/scenes.md` "How big a bed"): the shipped bed of
//! `config/robot_on_sand.yaml` is the rule's least bed, so more sand must not change the robot's
//! speed. Measured by `sandstep sweep`: the hexapod with C-legs at 2 Hz (dx = 1.25 cm, sleeping
//! sand on so that the extra sand costs little), 1 gait cycle after 0.5 s, from two starts 2 mm
//! apart, on the shipped 6 cm bed and on one 9 cm deep and 8 cm longer behind (the bed's width
//! made no difference: docs/speed-vs-accuracy.md). About 4 minutes on 2 cores.

mod sweep_support;
use sweep_support::{num, run_sweep};

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
    # Deeper (9 cm instead of 6) and longer behind (from -20 cm instead of -12).
    reference:
      - "sand.domain.min_m=[-0.2, -0.12, -0.09]"
      - "sand.bodies.0.box.min_m=[-0.2, -0.12, -0.09]"
      - robot.ground.height_m=-0.09
    settle_s: 0.5
    cycles: 1
    starts: 2
"#;

#[test]
fn robot_walks_as_fast_on_the_rules_bed_as_on_a_larger_one() {
    let sweep = run_sweep(SWEEP);
    let report = &sweep.report;
    let results = report["results"].as_array().unwrap();
    assert_eq!(report["failed"], 0, "{results:#?}");
    let [larger, shipped] = [0, 1].map(|i| &results[i]);
    assert_eq!(larger["setting"], "reference");
    let f = num;
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
    assert!(f(larger, "particles") > 1.5 * f(shipped, "particles"));
    let bound = NOISE_MULTIPLE * f(shipped, "relative_error_noise") + SPEED_TOLERANCE;
    assert!(
        f(shipped, "relative_error") < bound,
        "more sand changes the speed by more than {:.0} %: {shipped}",
        100.0 * bound
    );
}
