//! The robot walking on sand: the MPM solver and the rapier robot advance together, one rapier
//! step per sand substep of the same dt, through the CPIC coupling (`docs/physics.md`, section 4).

use std::time::Instant;

use serde_json::json;

use super::config::CouplingConfig;
use super::run::{progress_bar, robot_metrics_json, RunError, RunOptions, RunSummary};
use super::Scene;
use crate::coupling::{body_surfaces, Coupling, CouplingError, SandCollider};
use crate::robot::geometry::LEGS;
use crate::robot::{RobotConfig, RobotSim};

/// The robot's colliders as the sand sees them: each leg (a chain of thin collision boxes) as
/// one sheet, the body's colliders as solids.
pub fn robot_coupling(
    robot: &RobotSim,
    cfg: &CouplingConfig,
    dx: f32,
) -> Result<Coupling, CouplingError> {
    let world = robot.world();
    let parts = std::iter::once(("body".to_string(), robot.body_handle(), cfg.body)).chain(
        LEGS.iter()
            .zip(robot.leg_handles())
            .map(|(leg, h)| (leg.link_name(), h, cfg.legs)),
    );
    let mut colliders = Vec::new();
    for (name, body, mode) in parts {
        let surfaces =
            body_surfaces(body, &world.bodies, &world.colliders, dx).map_err(|message| {
                CouplingError::Surface {
                    name: name.clone(),
                    message,
                }
            })?;
        for (pose, surface) in surfaces {
            colliders.push(SandCollider {
                name: name.clone(),
                body,
                body_to_surface: pose,
                surface,
                friction: cfg.friction,
                mode,
            });
        }
    }
    Ok(Coupling::new(colliders, &world.bodies)?.with_method(cfg.method))
}

/// Depth (m) of the deepest leg point below `surface_z`, or 0.
fn leg_sinkage_m(robot: &RobotSim, surface_z: f32) -> f64 {
    let world = robot.world();
    let lowest = robot
        .leg_handles()
        .iter()
        .flat_map(|&h| world.bodies[h].colliders().iter().copied())
        .map(|c| world.colliders[c].compute_aabb().mins.z)
        .fold(f32::INFINITY, f32::min);
    (surface_z - lowest).max(0.0) as f64
}

/// Runs a scene with both `robot` and `sand`.
pub(super) fn run_robot_on_sand(
    scene: &Scene,
    robot_cfg: &RobotConfig,
    opts: &RunOptions,
) -> Result<RunSummary, RunError> {
    let config = &scene.config;
    let mut solver = scene
        .build_solver()
        .ok_or_else(|| RunError::Empty(scene.file.display().to_string()))?;
    let dx = solver.grid().dx;
    let mut robot = RobotSim::new(robot_cfg, config.gravity_m_s2)?;
    let coupling = robot_coupling(&robot, &config.coupling, dx)?;
    let surface_z = solver
        .particles
        .position
        .iter()
        .map(|x| x.z)
        .fold(f32::NEG_INFINITY, f32::max);

    let duration = opts.duration_s.unwrap_or(config.duration_s);
    let frame_interval = config.output.frame_interval_s;
    let frames = (duration / frame_interval).ceil().max(1.0) as u64;
    let bar = progress_bar(opts.progress, duration);
    let wall = Instant::now();
    let (mut particle_steps, mut sinkage_sum) = (0u64, 0.0f64);
    for frame in 1..=frames {
        let target = (frame as f64 * frame_interval).min(duration);
        while solver.time_s < target - 1e-12 {
            let remaining = (target - solver.time_s) as f32;
            let dt = solver
                .next_dt()
                .min(coupling.max_dt_s(&robot.world().bodies, dx))
                .min(remaining);
            coupling
                .substep(&mut solver, &mut robot.world_mut().bodies, dt)
                .inspect_err(|_| bar.abandon())?;
            robot.step(dt);
            particle_steps += solver.particles.len() as u64;
        }
        sinkage_sum += leg_sinkage_m(&robot, surface_z);
        bar.set_position((target * 1000.0) as u64);
        bar.set_message(format!(
            "step {} dt {:.2e} s",
            solver.steps,
            solver.next_dt()
        ));
    }
    bar.finish_and_clear();
    let wall_time_s = wall.elapsed().as_secs_f64();

    let mut metrics = robot_metrics_json(&robot);
    metrics.insert("mean_sinkage_m".into(), json!(sinkage_sum / frames as f64));
    metrics.insert("sand_mass_kg".into(), json!(solver.particles.total_mass()));
    metrics.insert("robot_mass_kg".into(), json!(robot.total_mass_kg()));
    metrics.insert("dx_m".into(), json!(dx));
    Ok(RunSummary::of_solver(
        &config.name,
        &solver,
        wall_time_s,
        particle_steps,
        metrics,
    ))
}
