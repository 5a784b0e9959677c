//! Sand against rigid bodies (CPIC, `docs/physics.md` section 4): leaks through thin parts,
//! momentum exchange. (CPIC against the plain grid boundary: `tests/stability.rs`.)

use nalgebra::Vector3;
use rapier3d::glamx::Vec3;
use rapier3d::prelude::{
    ColliderBuilder, PhysicsWorld, RigidBodyBuilder, RigidBodyHandle, RigidBodySet, SharedShape,
};
use sandstep::coupling::{Coupling, CouplingMode, CpicSurface, LoadPrediction};
use sandstep::mpm::Solver;
use sandstep::terrain::plate::{depth_cell_means, fit_line, press_plate, PlatePress};

mod sand_support;
use sand_support::{collider, run, sand_solver, solver, DX, SAND};

/// A free rigid box (two-way) thrown into a free blob of sand, no gravity: the momentum the box
/// loses is the momentum the sand gains, with either transfer and either CPIC band. (With AFLIP
/// the particles beside the collider's band once kept the band's velocity as a deviation: 34 %
/// drift.)
#[test]
fn box_thrown_into_sand_conserves_momentum() {
    for settings in [
        "transfer: apic",
        "transfer: aflip",
        "transfer: aflip, cpic_band: pic",
    ] {
        box_thrown_into_sand(settings);
    }
}

/// The substep and the CPIC band (`sand.solver.cpic_band`, `docs/speed-vs-accuracy.md`, "The
/// CPIC band"): a plough's drag with 3 x the substeps. With the default band (transferred as
/// the bulk, its deviation relaxed over 0.5 ms; the test sand damped in its cone) the drag does
/// not move (measured 2026-12-04: 1.1804 and 1.1809 N, +0.04 %; +0.22 % before the viscous
/// stress was kept in the cone); with the band's plain PIC it grows (1.6325 and 1.8078 N,
/// +10.7 %): PIC loses the band's velocity variation at
/// every substep, which made the answers near colliders follow the step count. Four ploughs,
/// about 2 minutes on 2 cores.
#[test]
fn a_ploughs_drag_does_not_follow_the_substep_but_with_the_cpic_bands_pic() {
    // The default step at this sand is about 1.35e-4 s (CFL 0.4); a third of it:
    let third_step = "max_dt_s: 4.5e-5";
    let drag = |settings: &str| sand_support::plough(settings, 0.0).mean_drag_n;
    let change = |band: &str| {
        let default_step = drag(&format!("cpic_band: {band}"));
        let small_step = drag(&format!("cpic_band: {band}, {third_step}"));
        println!(
            "cpic_band {band}: drag {default_step:.4} N, with a third of the step \
             {small_step:.4} N"
        );
        small_step / default_step - 1.0
    };
    let bulk = change("bulk");
    assert!(
        bulk.abs() < 0.01,
        "drag changed by {:.2} % with the band as the bulk",
        100.0 * bulk
    );
    let pic = change("pic");
    assert!(
        pic > 0.05,
        "drag changed by {:.2} % with the band's PIC",
        100.0 * pic
    );
}

fn box_thrown_into_sand(solver_settings: &str) {
    let mut sand = sand_solver(
        [0.16, 0.08, 0.08],
        [0.0, 0.0, 0.0],
        solver_settings,
        SAND,
        "[{material: sand, box: {min_m: [0.06, 0.025, 0.025], max_m: [0.09, 0.055, 0.055]}}]",
    );
    let box_mass = 0.04;
    let v0 = 1.0;
    let mut bodies = RigidBodySet::new();
    let cube = bodies.insert(
        RigidBodyBuilder::dynamic()
            .translation(Vec3::new(0.03, 0.04, 0.04))
            .linvel(Vec3::new(v0, 0.0, 0.0)),
    );
    let surface = CpicSurface::Solid(SharedShape::cuboid(0.01, 0.01, 0.01));
    let mut coupling = Coupling::new(
        vec![collider("box", cube, surface, CouplingMode::TwoWay)],
        &bodies,
    )
    .unwrap();
    let total = |sand: &Solver, bodies: &RigidBodySet| {
        let v = bodies[cube].linvel();
        sand.particles.total_momentum()
            + Vector3::new(v.x, v.y, v.z).cast::<f64>() * box_mass as f64
    };
    let p0 = total(&sand, &bodies);
    let mut worst = 0.0f64;
    let mut t = 0.0;
    while t < 0.06 {
        t += 0.005;
        run(
            &mut sand,
            &mut coupling,
            &mut bodies,
            t,
            Some((cube, box_mass)),
        );
        worst = worst.max((total(&sand, &bodies) - p0).norm() / p0.norm());
    }
    let v_box = bodies[cube].linvel().x;
    println!(
        "{solver_settings}: box {v0} -> {v_box} m/s, worst momentum drift {:.3} %",
        worst * 100.0
    );
    assert!(
        v_box < 0.8 * v0,
        "the box must have hit the sand (v = {v_box} m/s)"
    );
    assert!(
        sand.particles.total_momentum().x > 0.2 * box_mass as f64 * v0 as f64,
        "the sand must have been pushed"
    );
    assert!(
        worst < 0.01,
        "{solver_settings}: momentum drifted by {:.2} %",
        worst * 100.0
    );
}

/// A horizontal plate pressed slowly into a settled sand bed meets a resistance that grows about
/// linearly with depth (granular hydrostatics, as in resistive force theory).
#[test]
fn plate_pressed_into_sand_resists_linearly_with_depth() {
    let surface_z = 0.035;
    let mut sand = solver(
        [0.05, 0.05, 0.05],
        [0.0, 0.0, -9.81],
        &format!(
            "[{{material: sand, box: {{min_m: [0, 0, 0], max_m: [0.05, 0.05, {surface_z}]}}}}]"
        ),
    );
    // Settle under gravity first.
    let settled = 0.05;
    sand.advance_to(settled).unwrap();
    // A 16 mm square plate, 1 mm thick: a sheet, pressed at 0.1 m/s to 20 mm depth.
    let final_depth = 0.02;
    let press = PlatePress {
        start_m: [0.025, 0.025, surface_z],
        half_extents_m: [0.008, 0.008, 0.0005],
        speed_m_s: 0.1,
        final_depth_m: final_depth,
        window_s: 0.001,
        friction: 0.3,
    };
    // (depth (m), upward force of the sand on the plate (N)) averaged over 1 ms windows.
    let samples = press_plate(&mut sand, &press).unwrap();
    // The force saws with the grid period as the plate passes node planes (a CPIC artefact:
    // the incompatible nodes change at each plane), so fit the mean force over each cell of
    // depth.
    let cells = depth_cell_means(&samples, DX as f64, final_depth as f64);
    let points: Vec<(f64, f64)> = cells.iter().map(|c| (c.depth_m, c.force_n)).collect();
    let fit = fit_line(&points, false);
    let (slope, intercept, r2) = (fit.slope, fit.intercept, fit.r_squared);
    let mx = points.iter().map(|(x, _)| x).sum::<f64>() / points.len() as f64;
    let table: Vec<String> = points
        .iter()
        .map(|(d, f)| format!("{:.1} mm: {f:.2} N", d * 1e3))
        .collect();
    println!(
        "plate force vs depth (cell means): slope {slope:.0} N/m, intercept {intercept:.2} N, \
         R^2 {r2:.3}; {}",
        table.join(", ")
    );
    assert!(
        slope > 0.0,
        "resistance must grow with depth (slope {slope} N/m)"
    );
    assert!(r2 > 0.9, "force is not linear in depth: R^2 = {r2}");
    // Nearly through the origin: little resistance before contact.
    assert!(
        intercept.abs() < 0.3 * slope * mx,
        "intercept {intercept} N"
    );
}

/// Sand bed `[0, 0.06]^2 x [0, depth]` in a domain 5 cm tall, with gravity.
fn sand_bed(depth: f32) -> Solver {
    solver(
        [0.06, 0.06, 0.05],
        [0.0, 0.0, -9.81],
        &format!("[{{material: sand, box: {{min_m: [0, 0, 0], max_m: [0.06, 0.06, {depth}]}}}}]"),
    )
}

/// How a body moved over a watched interval.
struct Motion {
    /// Largest speed (m/s).
    fastest_m_s: f32,
    /// Largest spin (rad/s).
    max_spin_rad_s: f32,
    /// Root mean square spin over the substeps (rad/s).
    rms_spin_rad_s: f64,
}

/// Advances sand and a rapier world together, one rapier step per sand substep, to `until_s`,
/// watching `body` from `watch_from_s` on.
fn run_world(
    sand: &mut Solver,
    coupling: &mut Coupling,
    world: &mut PhysicsWorld,
    until_s: f64,
    body: RigidBodyHandle,
    watch_from_s: f64,
) -> Motion {
    let (mut fastest, mut spin) = (0.0f32, 0.0f32);
    let (mut spin_squares, mut substeps) = (0.0f64, 0u32);
    while sand.time_s < until_s {
        let dt = sand.next_dt().min(coupling.max_dt_s(&world.bodies, DX));
        coupling.substep(sand, &mut world.bodies, dt).unwrap();
        world.integration_parameters.dt = dt;
        world.step();
        if sand.time_s >= watch_from_s {
            let w = world.bodies[body].angvel().length();
            fastest = fastest.max(world.bodies[body].linvel().length());
            spin = spin.max(w);
            spin_squares += (w as f64).powi(2);
            substeps += 1;
        }
    }
    Motion {
        fastest_m_s: fastest,
        max_spin_rad_s: spin,
        rms_spin_rad_s: (spin_squares / substeps.max(1) as f64).sqrt(),
    }
}

fn world_with(
    body: RigidBodyBuilder,
    collider: ColliderBuilder,
) -> (PhysicsWorld, RigidBodyHandle) {
    let mut world = PhysicsWorld::new();
    world.gravity = Vec3::new(0.0, 0.0, -9.81);
    let (handle, _) = world.insert(body, collider);
    (world, handle)
}

/// A steel ball (1 cm radius) dropped from 2 cm onto a sand bed sinks in and comes to rest.
#[test]
fn dropped_sphere_sinks_and_comes_to_rest() {
    let depth = 0.03;
    let mut sand = sand_bed(depth);
    sand.advance_to(0.05).unwrap();
    let radius = 0.01;
    let (mut world, ball) = world_with(
        RigidBodyBuilder::dynamic().translation(Vec3::new(0.03, 0.03, depth + radius + 0.02)),
        ColliderBuilder::ball(radius).density(7800.0),
    );
    let surface = CpicSurface::Solid(SharedShape::ball(radius));
    let mut coupling = Coupling::new(
        vec![collider("ball", ball, surface, CouplingMode::TwoWay)],
        &world.bodies,
    )
    .unwrap();
    let impact_speed = run_world(&mut sand, &mut coupling, &mut world, 0.12, ball, 0.0).fastest_m_s;
    // It bounces twice (this test sand is soft, E = 0.35 MPa) and is at rest by 0.4 s.
    let late_speed = run_world(&mut sand, &mut coupling, &mut world, 0.5, ball, 0.4).fastest_m_s;
    let z_end = world.bodies[ball].translation().z;
    let sinkage = depth - (z_end - radius);
    println!(
        "ball: impact {impact_speed:.3} m/s, sinkage {:.1} mm, speed from 0.4 s on below \
         {late_speed:.4} m/s",
        sinkage * 1e3,
    );
    assert!(
        impact_speed > 0.5,
        "the ball must fall onto the sand ({impact_speed} m/s)"
    );
    assert!(sinkage > 0.001, "the ball must sink in ({sinkage} m)");
    assert!(
        z_end - radius > 0.005,
        "the ball must not sink to the floor"
    );
    // At rest: the largest speed in (0.4, 0.5] s is jitter, 0.0035 +- 0.0003 m/s over eight
    // starts 7 um apart (2026-12-04, sixth session, the CPIC penalty shared with the ball):
    // 0.0030 to 0.0039, this start 0.0037, 74 spreads from the bound, under 1 % of the impact
    // speed. (Before the shared penalty: 0.0047 +- 0.0043, this start ringing at 0.0154.) The
    // bound is far below the bounces' 0.09 m/s in (0.25, 0.35] s. Undamped, with the band as
    // the bulk, the ball bounced at 20 Hz for ever (0.054 m/s).
    assert!(
        late_speed < 0.025,
        "the ball must come to rest (speed {late_speed} m/s)"
    );
}

/// The 2 g plate of [`light_body_rests_on_sand_without_jitter`] resting on the sand bed, its
/// start shifted by `offset_m` along x and y, with the yield taking its velocity as
/// `prediction` says: its motion over (0.6, 1.0] s and its height at the end (m).
fn resting_plate(prediction: LoadPrediction, offset_m: f32) -> (Motion, f32) {
    let depth = 0.02;
    let mut sand = sand_bed(depth);
    sand.advance_to(0.05).unwrap();
    let half = [0.01, 0.01, 0.002];
    let (mut world, plate) = world_with(
        RigidBodyBuilder::dynamic().translation(Vec3::new(
            0.03 + offset_m,
            0.03 + offset_m,
            depth + half[2],
        )),
        // 1.6 cm^3 at 1250 kg/m^3: 2 g.
        ColliderBuilder::cuboid(half[0], half[1], half[2]).density(1250.0),
    );
    let mass = world.bodies[plate].mass();
    assert!((mass - 0.002).abs() < 1e-4, "mass {mass} kg");
    let surface = CpicSurface::Solid(SharedShape::cuboid(half[0], half[1], half[2]));
    let mut coupling = Coupling::new(
        vec![collider("plate", plate, surface, CouplingMode::TwoWay)],
        &world.bodies,
    )
    .unwrap()
    .with_load_prediction(prediction);
    // Settling, then the rocking watched over (0.6, 1.0] s.
    run_world(&mut sand, &mut coupling, &mut world, 0.6, plate, 0.6);
    let late = run_world(&mut sand, &mut coupling, &mut world, 1.0, plate, 0.6);
    let z = world.bodies[plate].translation().z;
    println!(
        "2 g plate ({prediction:?}, offset {offset_m} m) in (0.6, 1.0] s: speed <= {:.4} m/s, \
         spin <= {:.3} rad/s, rms spin {:.3} rad/s, z {z:.5} m",
        late.fastest_m_s, late.max_spin_rad_s, late.rms_spin_rad_s
    );
    (late, z)
}

/// A 2 g plate resting on sand stays where it is, and the jitter of the explicit exchange of
/// impulses with a body this light does not grow.
#[test]
fn light_body_rests_on_sand_without_jitter() {
    let (depth, half) = (0.02, [0.01, 0.01, 0.002]);
    let (late, z) = resting_plate(LoadPrediction::None, 0.0);
    // Measured (2026-12-04, the default band transferred as the bulk, the sand damped in its
    // cone): at this start, edges and bottom on node planes, the plate keeps rocking, bounded.
    // Over (0.6, 1.0] s at four starts 7 um apart: rms spin 0.47 +- 0.04 rad/s, fastest
    // 8.5 +- 1.1 mm/s, fastest spin 1.67 +- 0.22 rad/s; the bounds are 40, 6.1 and 15 spreads
    // away. (With the viscous stress uncut: 0.56 +- 0.09 rad/s, 8.8 +- 1.3 mm/s; with the
    // band's PIC, 2026-12-03: 0.76 +- 0.19 rad/s and 6.9 +- 1.3 mm/s;
    // with the band as the bulk and no damping the plate rocked at 0.024 m/s.) A growing
    // instability of the explicit exchange doubles the spin within a window.
    assert!(
        late.fastest_m_s < 0.015,
        "the plate jitters at {} m/s",
        late.fastest_m_s
    );
    // The fastest spin, kept from the earlier test: 1.94 rad/s at this start (1.49 with the
    // viscous stress uncut, 2.19 with the band's PIC; APIC at most 1.63 over eight).
    assert!(
        late.max_spin_rad_s < 5.0,
        "the plate spins at {} rad/s",
        late.max_spin_rad_s
    );
    assert!(
        late.rms_spin_rad_s < 2.0,
        "the plate rocks at {} rad/s rms",
        late.rms_spin_rad_s
    );
    assert!(
        (z - (depth + half[2])).abs() < 0.005,
        "the plate sank or flew: z = {z} m"
    );
}

/// The plate's jitter is the lag of the explicit exchange: the yield meets the sand with the
/// plate's velocity before the step's gravity, which reaches the sand a substep late. With the
/// load predicted from the last substep (`LoadPrediction::LastSubstep`) the plate meets the
/// sand with the velocity it will have, and rests far more quietly.
#[test]
fn a_light_body_met_with_its_coming_load_rests_quietly() {
    let (late, z) = resting_plate(LoadPrediction::LastSubstep, 0.0);
    // Measured (2026-12-04) over (0.6, 1.0] s at four starts 7 um apart (offsets 0, 7, 14,
    // 21 um): fastest 2.35 +- 0.19 mm/s, rms spin 0.122 +- 0.002 rad/s, fastest spin 0.34
    // +- 0.03 rad/s; with the load not predicted (the default) 10.6 +- 1.5 mm/s, 0.50 +- 0.12
    // rad/s and 1.72 +- 0.40 rad/s. The bounds sit 14 and 53 spreads above the predicted
    // plate's and below the other's lowest (9.2 mm/s, 0.37 rad/s).
    assert!(
        late.fastest_m_s < 0.005,
        "the plate jitters at {} m/s",
        late.fastest_m_s
    );
    assert!(
        late.rms_spin_rad_s < 0.25,
        "the plate rocks at {} rad/s rms",
        late.rms_spin_rad_s
    );
    assert!(
        (z - 0.022).abs() < 0.001,
        "the plate sank or flew: z = {z} m"
    );
}
