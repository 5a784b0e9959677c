//! The terrain's wrenches on the robot (`Simulation::take_terrain_wrenches`, published as
//! `body_wrench` and `leg_wrenches/<leg>`) account for everything that holds it up: standing on
//! sand, the vertical forces on the body and the legs together carry the robot's weight (the
//! rigid ground lies under the bed, out of reach). Newton's second law over a window,
//! `mean F_z = M g + dp_z / T`, with the robot's vertical momentum change `dp_z` from the
//! body's velocity (the standing robot moves as one). The body stands nearly level and the legs
//! hang straight up or down, so the test checks the wrenches' sum, not the direction of each
//! one's rotation into its link's frame.

use std::path::Path;

use nalgebra::{UnitQuaternion, Vector3};
use sandstep::scene::{LinkWrench, Scene, Simulation};

const SCENE: &str = "config/robot_on_sand.yaml";
/// A bed just under the standing robot (it spans x = -8.5..+8.5 cm, y = -3..+3 cm), 6 cm deep
/// like the scene's, at the robot tests' grid (m), all sand awake, the whole bed simulated;
/// the legs held where they start (frequency 0).
const STANDING: [&str; 8] = [
    "sand.dx_m=0.0125",
    "sand.domain.min_m=[-0.12, -0.08, -0.06]",
    "sand.domain.max_m=[0.14, 0.08, 0.06]",
    "sand.bodies=[{material: sand, box: {min_m: [-0.12, -0.08, -0.06], max_m: [0.14, 0.08, 0.0]}}]",
    "sand.solver.sleep=null",
    "sand.window=null",
    "sand.solver.cfl=0.4",
    "robot.gait.frequency_hz=0",
];
/// The robot lands (from 1 mm above the sand) and comes to rest (s); the wrenches are then
/// averaged over `WINDOW_S` in intervals of `INTERVAL_S`, the bag's 100 Hz.
const SETTLE_S: f64 = 0.4;
const WINDOW_S: f64 = 0.2;
const INTERVAL_S: f64 = 0.01;
/// Largest gap between the mean vertical force and `M g + dp_z / T`, as a fraction of the
/// weight. Measured (2026-12-07, this test): MPM 0.8340 N (body 0.4080, legs 0.4260) and RFT
/// 0.8346 N (legs alone) against a weight of 0.8338 N, dp_z / T +0.0002 and +0.0001 N; on the
/// whole bed of `config/robot_on_sand.yaml` (a bag read by `sandstep analyze`, 0.4 to 0.8 s)
/// 0.834 N, the legs 0.494 N of it, the body 0.340 N.
const BALANCE_BOUND: f64 = 0.03;
/// Largest vertical momentum change over the window, `|dp_z| / T`, as a fraction of the
/// weight: the robot must be standing, or a robot in free fall (no force, `dp_z / T = -M g`)
/// would pass the balance.
const AT_REST_BOUND: f64 = 0.01;

/// The link's force (N) in world axes, from its frame.
fn world_force(wrench: &LinkWrench, orientation_xyzw: [f64; 4]) -> Vector3<f64> {
    let [x, y, z, w] = orientation_xyzw;
    let rotation = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
    rotation * Vector3::from(wrench.force_n)
}

/// Mean vertical force on the body and on the legs (N), the weight (N) and the robot's
/// vertical momentum change over the window divided by its length (N), standing on the terrain
/// `model` (`mpm` or `rft`).
fn standing_balance(model: &str) -> (f64, f64, f64, f64) {
    let mut overrides: Vec<String> = STANDING.iter().map(|s| s.to_string()).collect();
    overrides.push(format!("terrain.model={model}"));
    let scene = Scene::load(Path::new(SCENE), &overrides).unwrap();
    let mut sim = Simulation::new(&scene).unwrap();
    sim.advance_to(SETTLE_S).unwrap();
    sim.take_terrain_wrenches().expect("a robot on a terrain");
    let robot = sim.robot().unwrap();
    let mass_kg = robot.total_mass_kg();
    let gravity = -scene.config.gravity_m_s2[2] as f64;
    let start_vz = sim.robot_state().unwrap().base_linear_velocity_m_s[2];
    let (mut body_n, mut legs_n) = (0.0, 0.0);
    let intervals = (WINDOW_S / INTERVAL_S).round() as usize;
    for i in 1..=intervals {
        sim.advance_to(SETTLE_S + i as f64 * INTERVAL_S).unwrap();
        let wrenches = sim.take_terrain_wrenches().unwrap();
        let poses = sim.link_poses();
        body_n += world_force(&wrenches.body, poses[0].orientation_xyzw).z;
        for (wrench, pose) in wrenches.legs.iter().zip(&poses[1..]) {
            assert_eq!(wrench.link, pose.link);
            legs_n += world_force(wrench, pose.orientation_xyzw).z;
        }
    }
    let end_vz = sim.robot_state().unwrap().base_linear_velocity_m_s[2];
    let n = intervals as f64;
    (
        body_n / n,
        legs_n / n,
        mass_kg * gravity,
        mass_kg * (end_vz - start_vz) / WINDOW_S,
    )
}

fn assert_weight_carried(model: &str) {
    let (body_n, legs_n, weight_n, momentum_rate_n) = standing_balance(model);
    let expected = weight_n + momentum_rate_n;
    println!(
        "{model}: body {body_n:.4} N + legs {legs_n:.4} N = {:.4} N; weight {weight_n:.4} N, \
         dp/T {momentum_rate_n:+.4} N",
        body_n + legs_n
    );
    assert!(
        momentum_rate_n.abs() < AT_REST_BOUND * weight_n,
        "{model}: the robot must stand still: dp/T {momentum_rate_n:+.4} N"
    );
    assert!(
        (body_n + legs_n - expected).abs() < BALANCE_BOUND * weight_n,
        "{model}: the terrain's wrenches carry {:.4} N of a {weight_n:.4} N robot \
         (dp/T {momentum_rate_n:+.4} N)",
        body_n + legs_n
    );
}

#[test]
fn standing_on_sand_the_wrenches_carry_the_weight() {
    assert_weight_carried("mpm");
}

#[test]
fn standing_on_rft_terrain_the_wrenches_carry_the_weight() {
    assert_weight_carried("rft");
}
