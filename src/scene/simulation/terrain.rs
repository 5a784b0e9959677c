//! What the robot walks on while a [`super::Simulation`] runs: rigid ground, MPM sand coupled by
//! CPIC, or resistive force theory, and the one function that puts a terrain's load on the
//! robot and steps rapier by the same time ([`Terrain::step_robot`]).

use super::terrain_loads::{BodyImpulse, TerrainLoads};
use crate::coupling::Coupling;
use crate::mpm::Solver;
use crate::robot::RobotSim;
use crate::scene::error::RunError;
use crate::scene::sand_window::SandWindow;
use crate::terrain::rft::RftTerrain;

/// A frame that is a whole number of RFT steps up to this relative round-off takes that number.
const STEP_COUNT_SLACK: f64 = 1e-6;
/// On RFT ground the robot's collisions with the rigid floor are detected only while an
/// element centre may come within one element size plus this distance (m) of the floor.
/// Every point of a collider lies within about one element size of an element centre (a
/// face's element reaches half an element's diagonal; a thin leg's sheet, 0.58 of a size
/// plus half the leg's thickness), so this is the room left for a contact to form in a step.
const FLOOR_CONTACT_MARGIN_M: f64 = 0.01;
/// Sand substeps end within this much of the frame's end (s).
const FRAME_END_TOLERANCE_S: f64 = 1e-12;

/// The terrain of a simulation.
pub enum Terrain {
    /// Only rapier's ground plane under the robot (`robot.ground`).
    RigidGround,
    /// MPM sand, with or without a robot on it.
    Sand(Box<SandTerrain>),
    /// Resistive force theory on a flat surface (`terrain.model: rft`).
    Rft(Box<RftGround>),
}

/// MPM sand and, with a robot, its CPIC coupling to the robot's colliders.
pub struct SandTerrain {
    pub solver: Solver,
    /// The robot's colliders as the sand sees them; `None` for sand alone.
    pub coupling: Option<Coupling>,
    /// Height of the sand surface at the start (m).
    pub surface_z_m: f32,
    /// The sand window following the robot (`sand.window`), if any.
    pub window: Option<Box<SandWindow>>,
    /// Where the bed falls short of the bed rule at the start (`src/scene/bed.rs`).
    pub bed_shortfalls: Vec<String>,
    /// The bed (m, min and max corners) when the sand is box-shaped bodies.
    pub bed_m: Option<[[f64; 3]; 2]>,
    /// When the robot first reached a side of the bed, if it has.
    pub bed_edge: Option<BedEdge>,
}

/// The first time the robot's colliders reached a side of the sand bed (checked at the end of
/// every frame): from then on the robot is at or over the bed's edge, not on open sand.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct BedEdge {
    /// Simulated time of the frame's end (s).
    pub time_s: f64,
    /// The sides reached, as `src/scene/bed.rs` names them (`left side (+y)`, ...).
    pub sides: Vec<&'static str>,
}

/// The RFT terrain and its step.
pub struct RftGround {
    pub terrain: RftTerrain,
    /// Largest rapier step, each with one set of RFT forces (s): `terrain.rft.max_dt_s`.
    pub step_s: f64,
    /// Whether the robot's collisions with the floor may be switched off while it is far
    /// from it: every moving collider is on a body the terrain bounds
    /// ([`RftTerrain::covers_moving_colliders`]).
    pub floor_contacts_switchable: bool,
}

/// The steps of one frame: adaptive (the sand's CFL and coupling bounds, recomputed every
/// substep) or a whole number of equal steps fixed at the frame's start.
pub enum StepPlan {
    Adaptive { until_s: f64 },
    Equal { left: u64, dt_s: f64 },
}

impl Terrain {
    /// How the robot steps from `now_s` to `until_s` (s) on this terrain.
    pub fn plan(&self, robot: &RobotSim, now_s: f64, until_s: f64) -> StepPlan {
        match self {
            Terrain::Sand(_) => StepPlan::Adaptive { until_s },
            Terrain::Rft(rft) => {
                let remaining = until_s - now_s;
                if remaining <= 0.0 {
                    return StepPlan::Equal { left: 0, dt_s: 0.0 };
                }
                // Equal rapier steps of at most step_s, each with the forces of its start.
                let steps = (remaining / rft.step_s * (1.0 - STEP_COUNT_SLACK))
                    .ceil()
                    .max(1.0) as u64;
                StepPlan::Equal {
                    left: steps,
                    dt_s: remaining / steps as f64,
                }
            }
            Terrain::RigidGround => {
                // The frame in rapier's f32 time, in equal steps of at most robot.physics.max_dt_s.
                let (left, dt_s) = robot.equal_steps(((until_s - now_s) as f32) as f64);
                StepPlan::Equal { left, dt_s }
            }
        }
    }

    /// The next step of `plan` (s), or `None` when the frame is done.
    pub fn next_step_s(&self, plan: &mut StepPlan, robot: &RobotSim) -> Option<f64> {
        match plan {
            StepPlan::Equal { left, dt_s } => {
                let next = (*left > 0).then_some(*dt_s);
                *left = left.saturating_sub(1);
                next
            }
            StepPlan::Adaptive { until_s } => {
                let Terrain::Sand(sand) = self else {
                    unreachable!("adaptive steps are the sand's")
                };
                let solver = &sand.solver;
                if solver.time_s >= *until_s - FRAME_END_TOLERANCE_S {
                    return None;
                }
                let remaining = (*until_s - solver.time_s) as f32;
                // One rapier step per sand substep: at most the robot's largest step too.
                let mut dt = solver.next_dt().min(remaining).min(robot.max_dt_s() as f32);
                if let Some(coupling) = &sand.coupling {
                    dt = dt.min(coupling.max_dt_s(&robot.world().bodies, solver.grid().dx));
                }
                Some(dt as f64)
            }
        }
    }

    /// One step of `dt_s` seconds: the terrain's load on the robot over the step (the sand's
    /// CPIC substep, or the RFT forces with their implicit terms), then one rapier step of the
    /// same `dt_s`, which is what the load was computed for. This is the only place the two
    /// meet. The terrain's impulse on the body and each leg over the step is added to
    /// `terrain_loads`.
    pub fn step_robot(
        &mut self,
        robot: &mut RobotSim,
        dt_s: f64,
        terrain_loads: &mut TerrainLoads,
    ) -> Result<(), RunError> {
        // The motors' settings for the step first: the sand's exchange reads them
        // (`coupling.motor_impedance`).
        if !robot.begin_step(dt_s) {
            return Ok(());
        }
        let impulses = self.load(robot, dt_s)?;
        // Moved to the hips before the step moves the links.
        terrain_loads.add_step(robot, &impulses, dt_s);
        robot.finish_step(dt_s);
        Ok(())
    }

    /// The terrain's load on the robot for the step of `dt_s` seconds that
    /// [`RobotSim::begin_step`] set up, set as forces on its bodies, and the impulse on each
    /// body it touched.
    fn load(&mut self, robot: &mut RobotSim, dt_s: f64) -> Result<Vec<BodyImpulse>, RunError> {
        let impulses = match self {
            Terrain::RigidGround => Vec::new(),
            Terrain::Sand(sand) => {
                let coupling = sand.coupling.as_mut().expect("a robot on sand is coupled");
                let world = robot.world_mut();
                let impulses = coupling.substep_with_joints(
                    &mut sand.solver,
                    &mut world.bodies,
                    Some(&world.multibody_joints),
                    dt_s as f32,
                )?;
                coupling
                    .colliders()
                    .iter()
                    .zip(&impulses)
                    .map(|(c, j)| BodyImpulse {
                        body: c.body,
                        linear_n_s: j.linear_n_s,
                        angular_n_m_s: j.angular_n_m_s,
                    })
                    .collect()
            }
            Terrain::Rft(rft) => {
                // RFT needs no colliders: collision detection, most of a rapier step's cost
                // here, is only for the rigid floor, and only when the robot may reach it.
                if rft.floor_contacts_switchable {
                    let lowest = rft.terrain.lowest_reach_m(&robot.world().bodies, dt_s);
                    let margin = rft.terrain.params().element_size_m + FLOOR_CONTACT_MARGIN_M;
                    // Negated, so that a NaN height keeps the contacts on.
                    let far = lowest - robot.floor_height_m() >= margin;
                    robot.set_floor_contacts(!far);
                }
                let world = robot.world_mut();
                let wrenches =
                    rft.terrain
                        .apply(&mut world.bodies, &mut world.multibody_joints, dt_s);
                rft.terrain
                    .bodies()
                    .iter()
                    .zip(&wrenches)
                    .map(|(b, w)| BodyImpulse {
                        body: b.body,
                        linear_n_s: w.force_n * dt_s,
                        angular_n_m_s: w.torque_n_m * dt_s,
                    })
                    .collect()
            }
        };
        Ok(impulses)
    }

    /// The sand, if the terrain is sand.
    pub fn sand(&self) -> Option<&SandTerrain> {
        match self {
            Terrain::Sand(sand) => Some(sand),
            _ => None,
        }
    }
}
