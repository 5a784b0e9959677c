//! The hexapod on sand (`config/robot_on_sand.yaml`, coupled with CPIC): with C-legs it walks
//! forward, and faster than with reversed legs at equal mass (Li, Zhang and Goldman 2013; Hu et
//! al. 2018, supplement section 4). The shipped scene (2 Hz) on a coarser grid (dx = 1.25 cm
//! instead of 1 cm): each run takes about two minutes on 2 cores.

use std::path::Path;

use sandstep::scene::{run_scene, RunOptions, RunSummary, Scene};

/// The shipped scene with the given legs.
fn walk(urdf: &str) -> RunSummary {
    let overrides = ["sand.dx_m=0.0125".to_string(), format!("robot.urdf={urdf}")];
    let scene = Scene::load(Path::new("config/robot_on_sand.yaml"), &overrides).unwrap();
    run_scene(&scene, &RunOptions::default()).unwrap()
}

fn metric(s: &RunSummary, key: &str) -> f64 {
    s.metrics[key]
        .as_f64()
        .unwrap_or_else(|| panic!("metric {key}"))
}

#[test]
fn c_legs_walk_forward_and_faster_than_reversed_legs() {
    let c = walk("urdf/hexapod.urdf");
    let reversed = walk("urdf/hexapod_reversed.urdf");
    let (c_speed, r_speed) = (
        metric(&c, "mean_speed_m_s"),
        metric(&reversed, "mean_speed_m_s"),
    );
    println!(
        "C-legs {c_speed:.3} m/s (sinkage {:.1} mm, tilt {:.0} deg), reversed {r_speed:.3} m/s \
         (sinkage {:.1} mm, tilt {:.0} deg); {:.0} s wall per simulated s",
        metric(&c, "mean_sinkage_m") * 1e3,
        metric(&c, "max_tilt_deg"),
        metric(&reversed, "mean_sinkage_m") * 1e3,
        metric(&reversed, "max_tilt_deg"),
        c.wall_time_per_sim_s
    );
    assert!((c.sim_time_s - 2.0).abs() < 1e-9);
    let (c_mass, r_mass) = (
        metric(&c, "robot_mass_kg"),
        metric(&reversed, "robot_mass_kg"),
    );
    assert!(
        (c_mass - r_mass).abs() < 1e-6,
        "equal mass: {c_mass} vs {r_mass} kg"
    );
    assert!(c_speed > 0.02, "C-legs must walk forward: {c_speed} m/s");
    assert!(
        c_speed > 1.1 * r_speed,
        "C-legs {c_speed} m/s vs reversed {r_speed} m/s"
    );
    assert!(
        metric(&c, "max_tilt_deg") < 60.0,
        "the robot must not tip over"
    );
}
