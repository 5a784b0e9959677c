//! The robot on MPM sand takes one rapier step per sand substep (`Terrain::step_robot`), and
//! that step is at most `robot.physics.max_dt_s`: a smaller robot step makes the sand take the
//! same smaller substeps.

use std::path::Path;

use sandstep::scene::{run_scene, RunOptions, Scene};

/// The robot on a cropped 1.25 cm bed (the determinism test's small coupled run).
const SMALL_BED: [&str; 3] = [
    "sand.dx_m=0.0125",
    "sand.domain.max_m=[0.2, 0.12, 0.06]",
    "sand.bodies.0.box.max_m=[0.2, 0.12, 0.0]",
];

fn steps_with_robot_max_dt(max_dt_s: Option<f64>, duration_s: f64) -> u64 {
    let mut overrides: Vec<String> = SMALL_BED.iter().map(|s| s.to_string()).collect();
    if let Some(dt) = max_dt_s {
        overrides.push(format!("robot.physics.max_dt_s={dt}"));
    }
    let scene = Scene::load(Path::new("config/robot_on_sand.yaml"), &overrides).unwrap();
    let opts = RunOptions {
        duration_s: Some(duration_s),
        ..RunOptions::default()
    };
    let summary = run_scene(&scene, &opts).unwrap();
    assert!((summary.sim_time_s - duration_s).abs() < 1e-9);
    summary.steps
}

#[test]
fn the_robot_step_bounds_the_sand_substep() {
    let duration_s = 0.01;
    let free = steps_with_robot_max_dt(None, duration_s);
    // The sand's own step (CFL) is about 0.3 ms here: 1 ms does not bind.
    assert!(free < 200, "{free} substeps in {duration_s} s");
    let bound_s = 2.5e-5;
    let bound = steps_with_robot_max_dt(Some(bound_s), duration_s);
    assert!(
        bound as f64 >= duration_s / bound_s - 1.0,
        "{bound} substeps at most {bound_s} s each in {duration_s} s"
    );
}
