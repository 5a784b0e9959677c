//! One stepping interface over every kind of scene: sand alone, the robot on rigid ground, the
//! robot on sand (MPM, or resistive force theory with `terrain.model: rft`). The node and the headless run both drive a [`Simulation`] and read its plain
//! outputs (robot state, link poses, leg wrenches, the sand surface); they never see rapier or
//! the solver's internals.

use nalgebra::{UnitQuaternion, Vector3};
use rapier3d::prelude::{RigidBody, RigidBodyHandle};

use super::bed::BedRule;
use super::robot_sand::{leg_sinkage_m, robot_coupling};
use super::run::RunError;
use super::sand_window::SandWindow;
use super::terrain::{robot_rft_terrain, TerrainModel};
use super::Scene;
use crate::coupling::rft::{BodyWrench, RftTerrain};
use crate::coupling::Coupling;
use crate::mpm::Solver;
use crate::robot::geometry::{BODY_LINK, LEGS};
use crate::robot::{GaitCommand, RobotSim, RobotState};

/// Fastest the robot's body may move before the run is stopped as blown up (m/s): far above
/// anything a walking robot does, far below what a diverging rigid-body solve produces.
const ROBOT_BLOWUP_SPEED_M_S: f64 = 100.0;
/// A frame that is a whole number of RFT steps up to this relative round-off takes that number.
const STEP_COUNT_SLACK: f64 = 1e-6;

/// Pose of one link in the world (`odom`) frame.
#[derive(Clone, Debug, PartialEq)]
pub struct LinkPose {
    /// URDF link name.
    pub link: String,
    /// Link origin (m).
    pub position_m: [f64; 3],
    /// Orientation, unit quaternion `[x, y, z, w]`.
    pub orientation_xyzw: [f64; 4],
}

/// The sand's mean force and torque on one leg over an interval, in the leg link's frame.
#[derive(Clone, Debug, PartialEq)]
pub struct LegWrench {
    /// URDF link name of the leg.
    pub link: String,
    /// Force (N), leg link frame.
    pub force_n: [f64; 3],
    /// Torque about the link origin (the hip axis) (N m), leg link frame.
    pub torque_n_m: [f64; 3],
}

/// Sum of the sand's impulses on one body since the last read, about the link origin in world
/// axes.
#[derive(Clone, Copy, Debug, Default)]
struct ImpulseSum {
    linear_n_s: Vector3<f64>,
    angular_n_m_s: Vector3<f64>,
}

enum Kind {
    Sand {
        solver: Solver,
    },
    RobotOnGround {
        robot: Box<RobotSim>,
    },
    RobotOnSand {
        solver: Solver,
        robot: Box<RobotSim>,
        coupling: Coupling,
        /// Height of the sand surface at the start (m).
        surface_z_m: f32,
        /// The sand window following the robot (`sand.window`), if any.
        window: Option<Box<SandWindow>>,
        /// Where the bed falls short of the bed rule ([`BedRule`]) at the start.
        bed_shortfalls: Vec<String>,
        /// Per leg, in [`LEGS`] order.
        leg_impulses: Vec<ImpulseSum>,
        /// Simulated time the impulses were summed over (s).
        impulse_time_s: f64,
    },
    /// The robot on resistive force theory terrain (`terrain.model: rft`): the terrain's forces
    /// are recomputed before every rapier step.
    RobotOnRft {
        robot: Box<RobotSim>,
        terrain: RftTerrain,
        /// Largest rapier step, each with one set of RFT forces (s): `terrain.rft.max_dt_s`.
        step_s: f64,
        /// Per leg, in [`LEGS`] order.
        leg_impulses: Vec<ImpulseSum>,
        /// Simulated time the impulses were summed over (s).
        impulse_time_s: f64,
    },
}

/// Half side of the square of flat RFT surface that [`Simulation::sand_surface`] reports
/// around the robot (m): the robot's footprint with margin.
pub const RFT_SURFACE_HALF_SIDE_M: f32 = 0.2;

/// A scene, built and ready to step.
pub struct Simulation {
    kind: Kind,
    /// Substeps taken (sand substeps, or rapier steps without sand).
    steps: u64,
    /// Particle-steps taken (particles times sand substeps).
    particle_steps: u64,
}

impl Simulation {
    /// Builds the scene's sand, robot and coupling at time 0.
    pub fn new(scene: &Scene) -> Result<Self, RunError> {
        let config = &scene.config;
        if let (Some(robot_cfg), TerrainModel::Rft) = (&config.robot, config.terrain.model) {
            // The `sand` section is not simulated: no solver, no particles.
            let robot = Box::new(RobotSim::new(robot_cfg, config.gravity_m_s2)?);
            let terrain = robot_rft_terrain(&robot, &config.terrain.rft)?;
            return Ok(Simulation {
                kind: Kind::RobotOnRft {
                    step_s: config.terrain.rft.step_s(),
                    robot,
                    terrain,
                    leg_impulses: vec![ImpulseSum::default(); LEGS.len()],
                    impulse_time_s: 0.0,
                },
                steps: 0,
                particle_steps: 0,
            });
        }
        let kind = match (&config.robot, scene.build_solver()) {
            (None, Some(solver)) => Kind::Sand { solver },
            (None, None) => return Err(RunError::Empty(scene.file.display().to_string())),
            (Some(robot_cfg), None) => Kind::RobotOnGround {
                robot: Box::new(RobotSim::new(robot_cfg, config.gravity_m_s2)?),
            },
            (Some(robot_cfg), Some(mut solver)) => {
                let robot = Box::new(RobotSim::new(robot_cfg, config.gravity_m_s2)?);
                let window = scene
                    .sand()
                    .and_then(|s| s.window)
                    .map(|w| Box::new(SandWindow::new(scene, w, &mut solver, robot_x_m(&robot))));
                let coupling = robot_coupling(&robot, &config.coupling, solver.grid().dx)?;
                let bed_shortfalls = scene.bed_box_m().map_or(Vec::new(), |bed| {
                    BedRule::for_robot(&robot, bed[1][2]).shortfalls(bed)
                });
                let surface_z_m = solver
                    .particles
                    .position
                    .iter()
                    .map(|x| x.z)
                    .fold(f32::NEG_INFINITY, f32::max);
                Kind::RobotOnSand {
                    solver,
                    robot,
                    coupling,
                    surface_z_m,
                    window,
                    bed_shortfalls,
                    leg_impulses: vec![ImpulseSum::default(); LEGS.len()],
                    impulse_time_s: 0.0,
                }
            }
        };
        Ok(Simulation {
            kind,
            steps: 0,
            particle_steps: 0,
        })
    }

    /// Simulated time (s).
    pub fn time_s(&self) -> f64 {
        match &self.kind {
            Kind::Sand { solver } | Kind::RobotOnSand { solver, .. } => solver.time_s,
            Kind::RobotOnGround { robot } | Kind::RobotOnRft { robot, .. } => robot.time_s(),
        }
    }

    /// Advances to `target_s` seconds of simulated time (no-op if already there).
    pub fn advance_to(&mut self, target_s: f64) -> Result<(), RunError> {
        match &mut self.kind {
            Kind::Sand { solver } => {
                let steps = solver.advance_to(target_s)?;
                self.steps += steps;
                self.particle_steps += steps * solver.particles.len() as u64;
            }
            Kind::RobotOnGround { robot } => {
                let dt = target_s - robot.time_s();
                if dt > 0.0 {
                    let max_dt = robot.max_dt_s();
                    self.steps += (dt / max_dt).ceil().max(1.0) as u64;
                    robot.step(dt as f32);
                }
                check_robot(robot)?;
            }
            Kind::RobotOnSand {
                solver,
                robot,
                coupling,
                leg_impulses,
                impulse_time_s,
                window,
                ..
            } => {
                if let Some(window) = window {
                    window.follow(solver, robot_x_m(robot));
                }
                let dx = solver.grid().dx;
                while solver.time_s < target_s - 1e-12 {
                    let remaining = (target_s - solver.time_s) as f32;
                    let dt = solver
                        .next_dt()
                        .min(coupling.max_dt_s(&robot.world().bodies, dx))
                        .min(remaining);
                    let impulses = coupling.substep(solver, &mut robot.world_mut().bodies, dt)?;
                    accumulate_leg_impulses(robot, coupling, &impulses, leg_impulses);
                    *impulse_time_s += dt as f64;
                    robot.step(dt);
                    check_robot(robot)?;
                    self.steps += 1;
                    self.particle_steps += solver.particles.len() as u64;
                }
            }
            Kind::RobotOnRft {
                robot,
                terrain,
                step_s,
                leg_impulses,
                impulse_time_s,
            } => {
                let remaining = target_s - robot.time_s();
                if remaining > 0.0 {
                    // Equal rapier steps of at most step_s, each with the forces of its start.
                    let steps = (remaining / *step_s * (1.0 - STEP_COUNT_SLACK))
                        .ceil()
                        .max(1.0) as u64;
                    let dt = remaining / steps as f64;
                    for _ in 0..steps {
                        let world = robot.world_mut();
                        let wrenches =
                            terrain.apply(&mut world.bodies, &mut world.multibody_joints, dt);
                        accumulate_rft_leg_impulses(robot, terrain, &wrenches, dt, leg_impulses);
                        *impulse_time_s += dt;
                        robot.single_step(dt);
                        check_robot(robot)?;
                        self.steps += 1;
                    }
                }
            }
        }
        Ok(())
    }

    /// Gives the robot a new gait command, acting from the next step (no-op without a robot).
    pub fn command(&mut self, cmd: GaitCommand) {
        if let Some(robot) = self.robot_mut() {
            robot.command(cmd);
        }
    }

    /// The robot, if the scene has one.
    pub fn robot(&self) -> Option<&RobotSim> {
        match &self.kind {
            Kind::Sand { .. } => None,
            Kind::RobotOnGround { robot }
            | Kind::RobotOnSand { robot, .. }
            | Kind::RobotOnRft { robot, .. } => Some(robot),
        }
    }

    fn robot_mut(&mut self) -> Option<&mut RobotSim> {
        match &mut self.kind {
            Kind::Sand { .. } => None,
            Kind::RobotOnGround { robot }
            | Kind::RobotOnSand { robot, .. }
            | Kind::RobotOnRft { robot, .. } => Some(robot),
        }
    }

    /// The sand solver, if the scene has sand.
    pub fn solver(&self) -> Option<&Solver> {
        match &self.kind {
            Kind::Sand { solver } | Kind::RobotOnSand { solver, .. } => Some(solver),
            Kind::RobotOnGround { .. } | Kind::RobotOnRft { .. } => None,
        }
    }

    /// Where the sand bed falls short of the bed rule for the robot (`src/scene/bed.rs`): one
    /// line per side; empty if it meets it or the scene has no robot on sand.
    pub fn bed_shortfalls(&self) -> &[String] {
        match &self.kind {
            Kind::RobotOnSand { bed_shortfalls, .. } => bed_shortfalls,
            _ => &[],
        }
    }

    /// The sand window following the robot (`sand.window`), if the scene has one.
    pub fn sand_window(&self) -> Option<&SandWindow> {
        match &self.kind {
            Kind::RobotOnSand { window, .. } => window.as_deref(),
            _ => None,
        }
    }

    /// The robot's state, if the scene has one.
    pub fn robot_state(&self) -> Option<RobotState> {
        self.robot().map(RobotSim::state)
    }

    /// World poses of the body (`base_link`) and every leg link, body first.
    pub fn link_poses(&self) -> Vec<LinkPose> {
        let Some(robot) = self.robot() else {
            return Vec::new();
        };
        let bodies = &robot.world().bodies;
        let pose = |name: String, h: RigidBodyHandle| {
            let p = bodies[h].position();
            let (t, r) = (p.translation, p.rotation);
            LinkPose {
                link: name,
                position_m: [t.x as f64, t.y as f64, t.z as f64],
                orientation_xyzw: [r.x as f64, r.y as f64, r.z as f64, r.w as f64],
            }
        };
        std::iter::once(pose(BODY_LINK.to_string(), robot.body_handle()))
            .chain(
                LEGS.iter()
                    .zip(robot.leg_handles())
                    .map(|(leg, h)| pose(leg.link_name(), h)),
            )
            .collect()
    }

    /// The RFT terrain, if the robot walks on one (`terrain.model: rft`).
    pub fn rft_terrain(&self) -> Option<&RftTerrain> {
        match &self.kind {
            Kind::RobotOnRft { terrain, .. } => Some(terrain),
            _ => None,
        }
    }

    /// Whether [`Self::take_leg_wrenches`] reports the terrain's forces on the legs (the robot on
    /// MPM sand or on RFT terrain).
    pub fn has_leg_wrenches(&self) -> bool {
        matches!(
            self.kind,
            Kind::RobotOnSand { .. } | Kind::RobotOnRft { .. }
        )
    }

    /// The terrain's (MPM sand's or RFT's) mean wrench on each leg since the last call, in each
    /// leg link's frame; `None` on rigid ground or without a robot, and zero wrenches when no
    /// time has passed. Resets the sums.
    pub fn take_leg_wrenches(&mut self) -> Option<Vec<LegWrench>> {
        let (robot, leg_impulses, impulse_time_s) = match &mut self.kind {
            Kind::RobotOnSand {
                robot,
                leg_impulses,
                impulse_time_s,
                ..
            }
            | Kind::RobotOnRft {
                robot,
                leg_impulses,
                impulse_time_s,
                ..
            } => (robot, leg_impulses, impulse_time_s),
            _ => return None,
        };
        let elapsed = *impulse_time_s;
        let bodies = &robot.world().bodies;
        let wrenches = LEGS
            .iter()
            .zip(robot.leg_handles())
            .zip(leg_impulses.iter_mut())
            .map(|((leg, h), sum)| {
                let r = bodies[h].position().rotation;
                let to_link = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
                    r.w as f64, r.x as f64, r.y as f64, r.z as f64,
                ))
                .inverse();
                let mean = |v: Vector3<f64>| {
                    let v = to_link * v / elapsed.max(f64::MIN_POSITIVE);
                    if elapsed > 0.0 {
                        [v.x, v.y, v.z]
                    } else {
                        [0.0; 3]
                    }
                };
                let wrench = LegWrench {
                    link: leg.link_name(),
                    force_n: mean(sum.linear_n_s),
                    torque_n_m: mean(sum.angular_n_m_s),
                };
                *sum = ImpulseSum::default();
                wrench
            })
            .collect();
        *impulse_time_s = 0.0;
        Some(wrenches)
    }

    /// The top of the sand: for each `cell_m` x `cell_m` column that holds particles, the
    /// highest particle (x, y of the column centre, z of that particle) (m). On RFT terrain, the
    /// flat surface over the square of half side [`RFT_SURFACE_HALF_SIDE_M`] centred under the
    /// robot. `None` without sand or RFT terrain.
    pub fn sand_surface(&self, cell_m: f32) -> Option<Vec<[f32; 3]>> {
        if let Kind::RobotOnRft { robot, terrain, .. } = &self.kind {
            let centre = robot.world().bodies[robot.body_handle()].translation();
            let z = terrain.params().surface_height_m as f32;
            let n = (RFT_SURFACE_HALF_SIDE_M / cell_m).ceil().max(1.0) as i32;
            let at = |k: i32| (k as f32 + 0.5) * cell_m;
            return Some(
                (-n..n)
                    .flat_map(|j| (-n..n).map(move |i| (i, j)))
                    .map(|(i, j)| [centre.x + at(i), centre.y + at(j), z])
                    .collect(),
            );
        }
        let solver = self.solver()?;
        let positions = &solver.particles.position;
        let (mut min, mut max) = ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]);
        for p in positions {
            min = [min[0].min(p.x), min[1].min(p.y)];
            max = [max[0].max(p.x), max[1].max(p.y)];
        }
        if positions.is_empty() {
            return Some(Vec::new());
        }
        let columns = |a: usize| ((max[a] - min[a]) / cell_m).floor() as usize + 1;
        let (nx, ny) = (columns(0), columns(1));
        let mut top = vec![f32::NEG_INFINITY; nx * ny];
        for p in positions {
            let i = (((p.x - min[0]) / cell_m) as usize).min(nx - 1);
            let j = (((p.y - min[1]) / cell_m) as usize).min(ny - 1);
            let z = &mut top[j * nx + i];
            *z = z.max(p.z);
        }
        Some(
            top.iter()
                .enumerate()
                .filter(|(_, z)| z.is_finite())
                .map(|(k, &z)| {
                    let (i, j) = (k % nx, k / nx);
                    [
                        min[0] + (i as f32 + 0.5) * cell_m,
                        min[1] + (j as f32 + 0.5) * cell_m,
                        z,
                    ]
                })
                .collect(),
        )
    }

    /// Depth of the deepest leg point below the initial sand surface (MPM) or the RFT surface
    /// (m); `None` without sand or RFT terrain.
    pub fn leg_sinkage_m(&self) -> Option<f64> {
        match &self.kind {
            Kind::RobotOnSand {
                robot, surface_z_m, ..
            } => Some(leg_sinkage_m(robot, *surface_z_m)),
            Kind::RobotOnRft { robot, terrain, .. } => Some(leg_sinkage_m(
                robot,
                terrain.params().surface_height_m as f32,
            )),
            _ => None,
        }
    }

    /// SHA-256 (hex) of the bits of the simulated state: the time, every particle's position,
    /// velocity, affine matrix, deformation gradient and volume correction (in storage order),
    /// and every rigid body's pose and velocity (in rapier's order). Two runs agree bit for bit
    /// exactly when their digests agree (`docs/determinism.md`, `tests/determinism.rs`).
    pub fn state_digest(&self) -> String {
        use sha2::{Digest, Sha256};
        let mut hash = Sha256::new();
        let mut add = |values: &mut dyn Iterator<Item = f32>| {
            for v in values {
                hash.update(v.to_bits().to_le_bytes());
            }
        };
        add(&mut std::iter::once(self.time_s() as f32));
        if let Some(solver) = self.solver() {
            let p = &solver.particles;
            add(&mut p.position.iter().flat_map(|v| v.iter().copied()));
            add(&mut p.velocity.iter().flat_map(|v| v.iter().copied()));
            add(&mut p.affine.iter().flat_map(|m| m.iter().copied()));
            add(&mut p.deformation.iter().flat_map(|m| m.iter().copied()));
            add(&mut p.volume_correction.iter().copied());
        }
        if let Some(robot) = self.robot() {
            for (_, rb) in robot.world().bodies.iter() {
                let (t, r, v, w) = (rb.translation(), rb.rotation(), rb.linvel(), rb.angvel());
                add(&mut [
                    t.x, t.y, t.z, r.x, r.y, r.z, r.w, v.x, v.y, v.z, w.x, w.y, w.z,
                ]
                .into_iter());
            }
        }
        format!("{:x}", hash.finalize())
    }

    /// Substeps taken so far.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Particle-steps taken so far.
    pub fn particle_steps(&self) -> u64 {
        self.particle_steps
    }
}

/// Adds one substep's impulses on each leg, moved from the body's centre of mass to the link
/// origin: `L_o = L_com + (com - o) x J`.
fn accumulate_leg_impulses(
    robot: &RobotSim,
    coupling: &Coupling,
    impulses: &[crate::mpm::cpic::ColliderImpulse],
    sums: &mut [ImpulseSum],
) {
    let bodies = &robot.world().bodies;
    for (leg, &h) in robot.leg_handles().iter().enumerate() {
        for (c, j) in coupling.colliders().iter().zip(impulses) {
            if c.body == h {
                add_at_link_origin(&bodies[h], j.linear_n_s, j.angular_n_m_s, &mut sums[leg]);
            }
        }
    }
}

/// Adds one step's RFT wrenches on each leg, held for `dt_s` seconds, like
/// [`accumulate_leg_impulses`].
fn accumulate_rft_leg_impulses(
    robot: &RobotSim,
    terrain: &RftTerrain,
    wrenches: &[BodyWrench],
    dt_s: f64,
    sums: &mut [ImpulseSum],
) {
    let bodies = &robot.world().bodies;
    for (leg, &h) in robot.leg_handles().iter().enumerate() {
        for (b, w) in terrain.bodies().iter().zip(wrenches) {
            if b.body == h {
                add_at_link_origin(
                    &bodies[h],
                    w.force_n * dt_s,
                    w.torque_n_m * dt_s,
                    &mut sums[leg],
                );
            }
        }
    }
}

/// Adds an impulse (N s) and an angular impulse about the body's centre of mass (N m s), world
/// axes, to `sum`, moved to the link origin: `L_o = L_com + (com - o) x J`.
fn add_at_link_origin(
    rb: &RigidBody,
    linear_n_s: Vector3<f64>,
    angular_com_n_m_s: Vector3<f64>,
    sum: &mut ImpulseSum,
) {
    let com = rb.center_of_mass();
    let origin = rb.position().translation;
    let arm = Vector3::new(
        (com.x - origin.x) as f64,
        (com.y - origin.y) as f64,
        (com.z - origin.z) as f64,
    );
    sum.linear_n_s += linear_n_s;
    sum.angular_n_m_s += angular_com_n_m_s + arm.cross(&linear_n_s);
}

/// The robot body's x position (m): what the sand window follows.
fn robot_x_m(robot: &RobotSim) -> f32 {
    robot.metrics().final_position_m[0] as f32
}

/// Stops a robot whose body has left the finite or plausible range.
fn check_robot(robot: &RobotSim) -> Result<(), RunError> {
    let rb = &robot.world().bodies[robot.body_handle()];
    let (p, v) = (rb.translation(), rb.linvel());
    let speed = v.length() as f64;
    if !(p.is_finite() && speed.is_finite() && speed <= ROBOT_BLOWUP_SPEED_M_S) {
        return Err(RunError::RobotBlowUp {
            time_s: robot.time_s(),
            position_m: [p.x, p.y, p.z],
            speed_m_s: speed,
        });
    }
    Ok(())
}
