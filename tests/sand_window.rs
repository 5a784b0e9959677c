//! The sand window (`sand.window`) against the whole bed, measured by `sandstep sweep`: the
//! hexapod with C-legs at 2 Hz on `config/robot_on_sand.yaml`'s 92 cm bed (dx = 1.25 cm, the
//! experiment test's grid), 2 gait cycles after 0.5 s of settling, from two starts 2 mm apart.
//! With the window only the sand from 10 cm behind the body to 20 cm ahead is simulated; the
//! robot must walk as fast as on the whole bed (within the run-to-run spread of the speed,
//! docs/speed-vs-accuracy.md) while the window moves along and holds a fraction of the bed's
//! particles. About 4 minutes on 2 cores.

mod sweep_support;
use sweep_support::{num, run_sweep};

/// The speed's run-to-run spread is large (`docs/speed-vs-accuracy.md`): a change of the mean
/// speed counts when it exceeds this many standard errors...
const NOISE_MULTIPLE: f64 = 2.5;
/// ...plus this relative allowance.
const SPEED_TOLERANCE: f64 = 0.05;

const SWEEP: &str = r#"
name: window
studies:
  - name: window
    base_scene: config/robot_on_sand.yaml
    overrides: [sand.dx_m=0.0125]
    quantity: robot_speed
    reference: []
    baseline: false
    starts: 2
    settings:
      - name: window
        overrides: ["sand.window={behind_m: 0.1, ahead_m: 0.2, step_m: 0.05}"]
"#;

#[test]
fn robot_walks_as_fast_in_the_sand_window_as_on_the_whole_bed() {
    let sweep = run_sweep(SWEEP);
    let report = &sweep.report;
    let results = report["results"].as_array().unwrap();
    assert_eq!(report["failed"], 0, "{results:#?}");
    let [whole, window] = [0, 1].map(|i| &results[i]);
    assert_eq!(whole["setting"], "reference");
    let f = num;
    let speed = f(whole, "value");
    assert!(
        speed > 0.05,
        "the robot walks forward on the whole bed: {whole}"
    );
    eprintln!(
        "whole bed {speed:.4} +- {:.4} m/s, {} particles, {:.1} s/s; window {:.4} +- {:.4} m/s, \
         {} particles at the end, {:.1} s/s: change {:.1} +- {:.1} %",
        f(whole, "value_std"),
        whole["particles"],
        f(whole, "wall_time_per_sim_s"),
        f(window, "value"),
        f(window, "value_std"),
        window["particles"],
        f(window, "wall_time_per_sim_s"),
        100.0 * f(window, "relative_error"),
        100.0 * f(window, "relative_error_noise"),
    );
    let bound = NOISE_MULTIPLE * f(window, "relative_error_noise") + SPEED_TOLERANCE;
    assert!(
        f(window, "relative_error") < bound,
        "the window changes the speed by more than {:.0} %: {window}",
        100.0 * bound
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
