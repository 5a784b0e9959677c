//! One stepping interface over every kind of scene: an optional robot on a terrain (sand alone,
//! the robot on rigid ground, on MPM sand coupled by CPIC, or on resistive force theory ground
//! with `terrain.model: rft`). The node and the headless run both drive a [`Simulation`] and
//! read its plain outputs (robot state, link poses, the terrain's wrenches on the body and the
//! legs, the sand surface); they never see rapier or the solver's internals.

mod terrain;
mod terrain_loads;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use rapier3d::prelude::RigidBodyHandle;

use super::bed::{robot_box_m, sides_reached, BedRule};
use super::error::RunError;
use super::robot_sand::{leg_sinkage_m, robot_coupling};
use super::sand_window::SandWindow;
use super::Scene;
use crate::mpm::Solver;
use crate::robot::geometry::{BODY_LINK, LEGS};
use crate::robot::{GaitCommand, RobotSim, RobotState};
use crate::terrain::rft::{robot_terrain, RftTerrain};
use crate::terrain::TerrainModel;
pub use terrain::{BedEdge, RftGround, SandTerrain, Terrain};
use terrain_loads::TerrainLoads;
pub use terrain_loads::{LinkWrench, TerrainWrenches};

/// Fastest the robot's body may move before the run is stopped as blown up (m/s): far above
/// anything a walking robot does, far below what a diverging rigid-body solve produces.
const ROBOT_BLOWUP_SPEED_M_S: f64 = 100.0;

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

/// Bytes [`Simulation::state_digest`] gathers before each update of its hash.
const DIGEST_BUFFER_BYTES: usize = 1 << 16;

/// Half side of the square of flat RFT surface that [`Simulation::sand_surface`] reports
/// around the robot (m): the robot's footprint with margin.
pub const RFT_SURFACE_HALF_SIDE_M: f32 = 0.2;

/// A scene, built and ready to step: an optional robot on a terrain.
pub struct Simulation {
    robot: Option<Box<RobotSim>>,
    terrain: Terrain,
    /// The terrain's load on the body and each leg since the last
    /// [`Simulation::take_terrain_wrenches`].
    terrain_loads: TerrainLoads,
    /// Substeps taken (sand substeps, or rapier steps without sand).
    steps: u64,
    /// Particle-steps taken (particles times sand substeps).
    particle_steps: u64,
    /// A stop request (Ctrl-C), polled every substep and inside the sand's substeps: once
    /// set, [`Simulation::advance_to`] returns early ([`Solver::stop_on`]).
    stop: Arc<AtomicBool>,
}

impl Simulation {
    /// Builds the scene's terrain and robot at time 0.
    pub fn new(scene: &Scene) -> Result<Self, RunError> {
        Self::new_unless(scene, &Arc::new(AtomicBool::new(false)))
    }

    /// [`Simulation::new`], looking at `stop` between the stages of the build (the robot, the
    /// sand's fill, the coupling): once it is set, the build ends with
    /// [`RunError::StoppedLoading`] (the sand's fill looks at it every lattice plane). The
    /// simulation built polls it every substep, and its sand inside every substep.
    pub fn new_unless(scene: &Scene, stop: &Arc<AtomicBool>) -> Result<Self, RunError> {
        let unless_stopped = |stage: &'static str| match stop.load(Ordering::Relaxed) {
            true => Err(RunError::StoppedLoading(stage)),
            false => Ok(()),
        };
        super::memory::check(scene)?;
        let config = &scene.config;
        unless_stopped("loading the robot")?;
        let robot = match &config.robot {
            Some(cfg) => Some(Box::new(RobotSim::new(cfg, config.gravity_m_s2)?)),
            None => None,
        };
        unless_stopped("filling the sand")?;
        let terrain = match (&robot, config.terrain.model) {
            (Some(robot), TerrainModel::Rft) => {
                // The `sand` section is not simulated: no solver, no particles.
                let terrain = robot_terrain(robot, &config.terrain.rft)?;
                let world = robot.world();
                Terrain::Rft(Box::new(RftGround {
                    floor_contacts_switchable: terrain
                        .covers_moving_colliders(&world.bodies, &world.colliders),
                    terrain,
                    step_s: config.terrain.rft.step_s(),
                }))
            }
            _ => match scene
                .build_solver_unless(stop)
                .map_err(|_| RunError::StoppedLoading("filling the sand"))?
            {
                Some(mut solver) => {
                    solver.stop_on(stop.clone());
                    unless_stopped("coupling the robot to the sand")?;
                    Terrain::Sand(Box::new(sand_terrain(scene, solver, robot.as_deref())?))
                }
                None if robot.is_some() => Terrain::RigidGround,
                None => return Err(RunError::Empty(scene.file.display().to_string())),
            },
        };
        Ok(Simulation {
            robot,
            terrain,
            terrain_loads: TerrainLoads::default(),
            steps: 0,
            particle_steps: 0,
            stop: stop.clone(),
        })
    }

    /// Simulated time (s).
    pub fn time_s(&self) -> f64 {
        match (&self.terrain, &self.robot) {
            (Terrain::Sand(sand), _) => sand.solver.time_s,
            (_, Some(robot)) => robot.time_s(),
            (_, None) => 0.0,
        }
    }

    /// The stop request polled every substep (given to [`Simulation::new_unless`]; a request
    /// of its own, never set, otherwise).
    pub fn stop_request(&self) -> Arc<AtomicBool> {
        self.stop.clone()
    }

    /// Advances to `target_s` seconds of simulated time (no-op if already there), or less if
    /// a stop is requested ([`Simulation::new_unless`]). A stop inside the sand's G2P leaves
    /// part of the sand one substep ahead of [`Simulation::time_s`] ([`Solver::stop_on`]).
    ///
    /// With sand, runs on a worker of rayon's pool, so the substeps' parallel stages split
    /// their work there instead of each waking the pool from the calling thread and putting
    /// that thread to sleep until it is done (`docs/performance.md`, "The substeps on a worker
    /// thread"). Without sand nothing runs in parallel, and handing each frame to the pool
    /// and back cost RFT runs an eighth of their time: it runs on the calling thread.
    pub fn advance_to(&mut self, target_s: f64) -> Result<(), RunError> {
        match self.terrain {
            Terrain::Sand(_) => rayon::scope(|_| self.advance_on_worker(target_s)),
            Terrain::Rft(_) | Terrain::RigidGround => self.advance_on_worker(target_s),
        }
    }

    /// [`Simulation::advance_to`], on the thread it is called on.
    fn advance_on_worker(&mut self, target_s: f64) -> Result<(), RunError> {
        let Some(robot) = self.robot.as_deref_mut() else {
            let Terrain::Sand(sand) = &mut self.terrain else {
                return Ok(());
            };
            let steps = sand.solver.advance_to(target_s)?;
            self.steps += steps;
            self.particle_steps += steps * sand.solver.particles.len() as u64;
            return Ok(());
        };
        if let Terrain::Sand(sand) = &mut self.terrain {
            if let Some(window) = &mut sand.window {
                window.follow(&mut sand.solver, robot_x_m(robot));
            }
        }
        let mut plan = self.terrain.plan(robot, robot.time_s(), target_s);
        while let Some(dt_s) = self.terrain.next_step_s(&mut plan, robot) {
            if self.stop.load(Ordering::Relaxed) {
                break;
            }
            match self
                .terrain
                .step_robot(robot, dt_s, &mut self.terrain_loads)
            {
                // Stopped inside the sand's substep: the robot was not stepped (its gait and
                // motors were already set for the step: `RobotSim::begin_step`).
                Err(RunError::Sim(e)) if e.is_stop() => break,
                stepped => stepped?,
            }
            check_robot(robot)?;
            self.steps += 1;
            if let Terrain::Sand(sand) = &self.terrain {
                self.particle_steps += sand.solver.particles.len() as u64;
            }
        }
        if let Terrain::Sand(sand) = &mut self.terrain {
            if let (None, Some(bed_m)) = (&sand.bed_edge, sand.bed_m) {
                let sides = sides_reached(robot_box_m(robot), bed_m);
                if !sides.is_empty() {
                    sand.bed_edge = Some(BedEdge {
                        time_s: robot.time_s(),
                        sides,
                    });
                }
            }
        }
        Ok(())
    }

    /// Gives the robot a new gait command, acting from the next step (no-op without a robot).
    pub fn command(&mut self, cmd: GaitCommand) {
        if let Some(robot) = self.robot.as_deref_mut() {
            robot.command(cmd);
        }
    }

    /// The robot, if the scene has one.
    pub fn robot(&self) -> Option<&RobotSim> {
        self.robot.as_deref()
    }

    /// The sand solver, if the scene has sand.
    pub fn solver(&self) -> Option<&Solver> {
        self.terrain.sand().map(|sand| &sand.solver)
    }

    /// Where the sand bed falls short of the bed rule for the robot (`src/scene/bed.rs`): one
    /// line per side; empty if it meets it or the scene has no robot on sand.
    pub fn bed_shortfalls(&self) -> &[String] {
        self.terrain
            .sand()
            .map_or(&[], |sand| sand.bed_shortfalls.as_slice())
    }

    /// When the robot first reached a side of the sand bed, if it has (`src/scene/bed.rs`).
    pub fn bed_edge(&self) -> Option<&BedEdge> {
        self.terrain.sand().and_then(|sand| sand.bed_edge.as_ref())
    }

    /// The sand window following the robot (`sand.window`), if the scene has one.
    pub fn sand_window(&self) -> Option<&SandWindow> {
        self.terrain.sand().and_then(|sand| sand.window.as_deref())
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
        match &self.terrain {
            Terrain::Rft(rft) => Some(&rft.terrain),
            _ => None,
        }
    }

    /// Whether [`Self::take_terrain_wrenches`] reports the terrain's forces on the robot (the
    /// robot on MPM sand or on RFT terrain).
    pub fn has_terrain_wrenches(&self) -> bool {
        self.robot.is_some() && !matches!(self.terrain, Terrain::RigidGround)
    }

    /// The terrain's (MPM sand's or RFT's) mean wrench on the body and on each leg since the
    /// last call, each in its link's frame; `None` on rigid ground or without a robot, and zero
    /// wrenches when no time has passed. Resets the sums.
    pub fn take_terrain_wrenches(&mut self) -> Option<TerrainWrenches> {
        if !self.has_terrain_wrenches() {
            return None;
        }
        let robot = self.robot.as_deref()?;
        Some(self.terrain_loads.take_mean(robot))
    }

    /// The top of the sand: for each `cell_m` x `cell_m` column that holds particles, the
    /// highest particle (x, y of the column centre, z of that particle) (m). On RFT terrain, the
    /// flat surface over the square of half side [`RFT_SURFACE_HALF_SIDE_M`] centred under the
    /// robot. `None` without sand or RFT terrain.
    pub fn sand_surface(&self, cell_m: f32) -> Option<Vec<[f32; 3]>> {
        if let (Terrain::Rft(rft), Some(robot)) = (&self.terrain, self.robot()) {
            let centre = robot.world().bodies[robot.body_handle()].translation();
            let z = rft.terrain.params().surface_height_m as f32;
            let n = (RFT_SURFACE_HALF_SIDE_M / cell_m).ceil().max(1.0) as i32;
            let at = |k: i32| (k as f32 + 0.5) * cell_m;
            return Some(
                (-n..n)
                    .flat_map(|j| (-n..n).map(move |i| (i, j)))
                    .map(|(i, j)| [centre.x + at(i), centre.y + at(j), z])
                    .collect(),
            );
        }
        Some(surface_of(&self.solver()?.particles.position, cell_m))
    }

    /// Depth of the deepest leg point below the initial sand surface (MPM) or the RFT surface
    /// (m); `None` without a robot on sand or RFT terrain.
    pub fn leg_sinkage_m(&self) -> Option<f64> {
        let robot = self.robot()?;
        match &self.terrain {
            Terrain::Sand(sand) => Some(leg_sinkage_m(robot, sand.surface_z_m)),
            Terrain::Rft(rft) => Some(leg_sinkage_m(
                robot,
                rft.terrain.params().surface_height_m as f32,
            )),
            Terrain::RigidGround => None,
        }
    }

    /// SHA-256 (hex) of the bits of the simulated state: the time, every particle's position,
    /// velocity, affine matrix, deformation gradient and volume correction (in storage order),
    /// and every rigid body's pose and velocity (in rapier's order). Two runs agree bit for bit
    /// exactly when their digests agree (`docs/determinism.md`, `tests/determinism.rs`).
    pub fn state_digest(&self) -> String {
        use sha2::{Digest, Sha256};
        let mut hash = Sha256::new();
        // The values' little-endian bytes, handed to the hash a buffer at a time (value by
        // value, 6.8 M particles took 0.7 s).
        let mut buffer = Vec::with_capacity(DIGEST_BUFFER_BYTES);
        let mut add = |values: &mut dyn Iterator<Item = f32>| {
            for v in values {
                buffer.extend_from_slice(&v.to_bits().to_le_bytes());
                if buffer.len() >= DIGEST_BUFFER_BYTES {
                    hash.update(&buffer);
                    buffer.clear();
                }
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
        hash.update(&buffer);
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

/// The sand of `scene` as terrain: with a robot, coupled to its colliders by CPIC, with the
/// scene's sand window and the bed checked against the bed rule.
fn sand_terrain(
    scene: &Scene,
    mut solver: Solver,
    robot: Option<&RobotSim>,
) -> Result<SandTerrain, RunError> {
    let top = |solver: &Solver| {
        solver
            .particles
            .position
            .iter()
            .map(|x| x.z)
            .fold(f32::NEG_INFINITY, f32::max)
    };
    let Some(robot) = robot else {
        return Ok(SandTerrain {
            surface_z_m: top(&solver),
            solver,
            coupling: None,
            window: None,
            bed_shortfalls: Vec::new(),
            bed_m: None,
            bed_edge: None,
        });
    };
    let window = scene
        .sand()
        .and_then(|s| s.window)
        .map(|w| Box::new(SandWindow::new(scene, w, &mut solver, robot_x_m(robot))));
    let coupling = robot_coupling(robot, &scene.config.coupling, solver.grid().dx)?;
    let bed_m = scene.bed_box_m();
    let bed_shortfalls = bed_m.map_or(Vec::new(), |bed| {
        BedRule::for_robot(robot, bed[1][2]).shortfalls(bed)
    });
    let surface_z_m = top(&solver);
    Ok(SandTerrain {
        solver,
        coupling: Some(coupling),
        surface_z_m,
        window,
        bed_shortfalls,
        bed_m,
        bed_edge: None,
    })
}

/// The top of the particles at `positions`, per `cell_m` column ([`Simulation::sand_surface`]).
fn surface_of(positions: &[nalgebra::Vector3<f32>], cell_m: f32) -> Vec<[f32; 3]> {
    let (mut min, mut max) = ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]);
    for p in positions {
        min = [min[0].min(p.x), min[1].min(p.y)];
        max = [max[0].max(p.x), max[1].max(p.y)];
    }
    if positions.is_empty() {
        return Vec::new();
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
        .collect()
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
