//! The robot walking on sand: how the sand sees the robot's colliders through the CPIC coupling
//! (`docs/physics.md`, section 4). [`super::simulation::Simulation`] steps them together, one
//! rapier step per sand substep of the same dt.

use super::config::CouplingConfig;
use crate::coupling::{body_surfaces, Coupling, CouplingError, LegYield, SandCollider};
use crate::robot::geometry::LEGS;
use crate::robot::RobotSim;

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
            body_surfaces(body, &world.bodies, &world.colliders, dx).map_err(|source| {
                CouplingError::Surface {
                    name: name.clone(),
                    source,
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
    let coupling = Coupling::new(colliders, &world.bodies)?
        .with_method(cfg.method)
        .with_load_prediction(cfg.load_prediction);
    Ok(match cfg.legs_yield_with {
        LegYield::Leg => coupling,
        LegYield::Articulated if cfg.motor_impedance() => coupling
            .with_articulation()
            .with_motor_impedance(world.integration_parameters.num_solver_iterations),
        LegYield::Articulated => coupling.with_articulation(),
        // The body's own colliders then yield with the whole robot too.
        LegYield::Robot => coupling.with_rigid_group(
            std::iter::once(robot.body_handle())
                .chain(robot.leg_handles())
                .collect(),
            &world.bodies,
        )?,
    })
}

/// Depth (m) of the deepest leg point below `surface_z`, or 0.
pub fn leg_sinkage_m(robot: &RobotSim, surface_z: f32) -> f64 {
    let world = robot.world();
    let lowest = robot
        .leg_handles()
        .iter()
        .flat_map(|&h| world.bodies[h].colliders().iter().copied())
        .map(|c| world.colliders[c].compute_aabb().mins.z)
        .fold(f32::INFINITY, f32::min);
    (surface_z - lowest).max(0.0) as f64
}
