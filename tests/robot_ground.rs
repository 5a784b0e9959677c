//! The hexapod on flat rigid ground: it walks forward upright with its tripods half a cycle
//! apart, walks backward at a negative frequency, turns towards the slower side, obeys a
//! per-joint velocity override, and the shipped scene config runs.
//!
//! Rigid-ground runs use 1 Hz: at the published 4 Hz the rigid C-legs throw the robot into
//! short flights (leg-tip centripetal acceleration (2 pi f)^2 R exceeds g above 3.5 Hz), which
//! sand absorbs but rigid ground does not (docs/robot.md, "Rigid-ground stability").

use std::f64::consts::{PI, TAU};
use std::path::{Path, PathBuf};

use sandstep::robot::geometry::Tripod;
use sandstep::robot::{GaitCommand, RobotConfig, RobotSim, LEGS, LEG_COUNT};

const GRAVITY: [f32; 3] = [0.0, 0.0, -9.81];
/// Rigid-ground gait frequency (Hz), as in config/robot_on_ground.yaml.
const FREQUENCY_HZ: f64 = 1.0;
/// Sampling interval of the checks during a run (s).
const SAMPLE_S: f32 = 0.01;
/// Allowed deviation from the tripod pattern (deg).
const PHASE_TOLERANCE_DEG: f64 = 5.0;
/// Largest tilt of an upright robot (deg).
const UPRIGHT_DEG: f64 = 20.0;
/// Largest direction of travel off +x of a robot walking straight (deg): a sideways drift of
/// a tenth of the distance, the bound on the drift below.
const STRAIGHT_AHEAD_DEG: f64 = 5.7;

fn sim(frequency_hz: f64, turn_hz: f64) -> RobotSim {
    let mut cfg = RobotConfig {
        urdf: PathBuf::from("urdf/hexapod.urdf"),
        ..Default::default()
    };
    cfg.gait.frequency_hz = frequency_hz;
    cfg.gait.turn_frequency_difference_hz = turn_hz;
    cfg.validate(Path::new("tests/robot_ground.rs")).unwrap();
    RobotSim::new(&cfg, GRAVITY).unwrap()
}

fn wrap_pi(a: f64) -> f64 {
    let w = a.rem_euclid(TAU);
    if w > PI {
        w - TAU
    } else {
        w
    }
}

/// Largest deviation (deg) of the legs from the tripod pattern: each leg from its tripod's
/// first leg, and tripod B from tripod A + pi.
fn pattern_error_deg(q: &[f64]) -> f64 {
    let first = |t: Tripod| LEGS.iter().position(|l| l.tripod == t).unwrap();
    let (a, b) = (first(Tripod::A), first(Tripod::B));
    let mut worst: f64 = wrap_pi(q[b] - q[a] - PI).abs();
    for (i, leg) in LEGS.iter().enumerate() {
        let reference = if leg.tripod == Tripod::A { q[a] } else { q[b] };
        worst = worst.max(wrap_pi(q[i] - reference).abs());
    }
    worst.to_degrees()
}

#[test]
fn walks_forward_upright_with_the_tripods_half_a_cycle_apart() {
    let mut sim = sim(FREQUENCY_HZ, 0.0);
    let mut worst_phase_deg: f64 = 0.0;
    while sim.time_s() < 3.0 {
        sim.step(SAMPLE_S);
        let s = sim.state();
        worst_phase_deg = worst_phase_deg.max(pattern_error_deg(&s.joint_positions_rad));
        // The measured tripod phases agree with the joints.
        assert!(
            (wrap_pi(s.tripod_phase_rad[1] - s.tripod_phase_rad[0] - PI))
                .abs()
                .to_degrees()
                < PHASE_TOLERANCE_DEG
        );
    }
    let m = sim.metrics();
    println!("forward: {m:?}, worst tripod-pattern error {worst_phase_deg:.2} deg");
    assert!(
        worst_phase_deg < PHASE_TOLERANCE_DEG,
        "tripods drift {worst_phase_deg} deg from half a cycle apart"
    );
    assert!(
        m.mean_speed_m_s > 0.05,
        "mean speed {} m/s",
        m.mean_speed_m_s
    );
    assert!(
        m.max_tilt_deg < UPRIGHT_DEG,
        "tilted {} deg",
        m.max_tilt_deg
    );
    assert!(
        m.final_position_m[1].abs() < 0.1 * m.distance_m,
        "drifted sideways: {:?}",
        m.final_position_m
    );
    assert!(
        m.travel_direction_deg.abs() < STRAIGHT_AHEAD_DEG,
        "walked {} deg off +x",
        m.travel_direction_deg
    );
    // Counter-clockwise from +x: a robot that ends left of its start went off at a positive
    // angle (it starts at y = 0).
    assert_eq!(
        m.travel_direction_deg.signum(),
        m.final_position_m[1].signum(),
        "{m:?}"
    );
    // The legs turned at the commanded frequency: 3 cycles in 3 s.
    let q0 = sim.state().joint_positions_rad[0];
    assert!(
        (q0 / TAU - 3.0).abs() < 0.05,
        "leg 0 turned {} cycles",
        q0 / TAU
    );
}

#[test]
fn a_negative_frequency_walks_backward() {
    let mut sim = sim(-FREQUENCY_HZ, 0.0);
    sim.step(3.0);
    let m = sim.metrics();
    println!("backward: {m:?}");
    assert!(
        m.mean_speed_m_s < -0.05,
        "mean speed {} m/s",
        m.mean_speed_m_s
    );
}

#[test]
fn a_faster_right_side_turns_left_and_a_faster_left_side_turns_right() {
    for (difference_hz, sign) in [(0.3, 1.0), (-0.3, -1.0)] {
        let mut sim = sim(FREQUENCY_HZ, difference_hz);
        sim.step(3.0);
        let m = sim.metrics();
        println!("turn {difference_hz:+} Hz: {m:?}");
        assert!(
            m.yaw_change_deg * sign > 10.0,
            "difference {difference_hz} Hz: yaw {} deg",
            m.yaw_change_deg
        );
        assert!(m.distance_m > 0.1, "still walks forward: {}", m.distance_m);
        // A robot on an arc goes off in the direction it turns, by less than it turns.
        assert!(
            m.travel_direction_deg * sign > 0.0
                && m.travel_direction_deg * sign < m.yaw_change_deg * sign,
            "difference {difference_hz} Hz: went {} deg off +x, turned {} deg",
            m.travel_direction_deg,
            m.yaw_change_deg
        );
    }
}

#[test]
fn a_velocity_override_drives_each_joint_then_the_gait_resumes() {
    let mut sim = sim(FREQUENCY_HZ, 0.0);
    sim.step(0.5);
    // Left legs forward, right legs backward: turning on the spot.
    let speeds: [f64; LEG_COUNT] = std::array::from_fn(|i| if i < 3 { 4.0 } else { -4.0 });
    sim.command(GaitCommand {
        joint_velocity_override_rad_s: Some(speeds),
        ..sim.current_command()
    });
    let before = sim.state().joint_positions_rad;
    sim.step(1.0);
    let after = sim.state().joint_positions_rad;
    for i in 0..LEG_COUNT {
        let mean_speed = after[i] - before[i];
        assert!(
            (mean_speed - speeds[i]).abs() < 0.1 * speeds[i].abs(),
            "{}: {mean_speed} rad/s",
            LEGS[i].stem
        );
    }
    assert!(
        sim.metrics().yaw_change_deg < -10.0,
        "spins clockwise: {}",
        sim.metrics().yaw_change_deg
    );

    sim.command(GaitCommand {
        joint_velocity_override_rad_s: None,
        ..sim.current_command()
    });
    sim.step(1.0);
    let err = pattern_error_deg(&sim.state().joint_positions_rad);
    assert!(
        err < PHASE_TOLERANCE_DEG,
        "gait not resumed: {err} deg off the tripod pattern"
    );
}

#[test]
fn the_shipped_scene_runs_and_reports_metrics() {
    let path = Path::new("config/robot_on_ground.yaml");
    let scene: serde_yaml_ng::Value =
        serde_yaml_ng::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    let cfg: RobotConfig = serde_yaml_ng::from_value(scene["robot"].clone()).unwrap();
    cfg.validate(path).unwrap();
    let duration = scene["duration_s"].as_f64().unwrap();
    let mut sim = RobotSim::new(&cfg, GRAVITY).unwrap();
    sim.step(duration as f32);
    let json = serde_json::to_value(sim.metrics()).unwrap();
    for key in [
        "distance_m",
        "mean_speed_m_s",
        "final_position_m",
        "max_tilt_deg",
        "yaw_change_deg",
        "travel_direction_deg",
    ] {
        assert!(json.get(key).is_some(), "metric {key} missing: {json}");
    }
    assert!(json["mean_speed_m_s"].as_f64().unwrap() > 0.0, "{json}");
    assert!((sim.time_s() - duration).abs() < 1e-6);
}
