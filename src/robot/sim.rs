//! The hexapod in a rapier world on flat rigid ground, driven by the tripod gait.
//!
//! The robot is one rapier multibody (reduced coordinates): the body is the free-floating
//! root, each leg a continuous joint about +y with a torque-limited motor. See
//! docs/robot.md for why multibody rather than impulse joints.

use rapier3d::glamx::{Quat, Vec3};
use rapier3d::prelude::{
    ColliderBuilder, Group, InteractionGroups, InteractionTestMode, JointAxis, MotorModel,
    MultibodyJointHandle, PhysicsWorld, Pose, RigidBodyBuilder, RigidBodyHandle, SharedShape,
    Vector,
};
use rapier3d_urdf::{UrdfLoaderOptions, UrdfMultibodyOptions, UrdfRobot};
use serde::Serialize;

use super::config::RobotConfig;
use super::error::RobotError;
use super::gait::{circular_mean, DcMotor, GaitCommand, GaitController};
use super::geometry::{Tripod, LEGS, LEG_COUNT};
use super::loader::load_urdf;

/// The robot's colliders touch the ground (and anything else) but not each other: the links
/// of one robot never collide (`UrdfMultibodyOptions::DISABLE_SELF_CONTACTS`), so their pairs
/// are left out of the narrow phase too, where the legs' boxes overlapping the body at the
/// hips would otherwise cost a contact manifold each per step.
const ROBOT_COLLISION_GROUPS: InteractionGroups = InteractionGroups::new(
    Group::GROUP_1,
    Group::ALL.difference(Group::GROUP_1),
    InteractionTestMode::And,
);

/// Index of a revolute joint's angle in rapier's 6-entry joint coordinates (after x, y, z).
const ANG_X_COORD: usize = 3;
/// Viscous damping on every joint coordinate of the robot (N m s/rad, or N s/m for the body's
/// free translation): none; friction lives in the motor model.
const MULTIBODY_DOF_DAMPING: f32 = 0.0;
/// Restitution of every contact: ABS on ground barely bounces.
const RESTITUTION: f32 = 0.0;

/// Plain-data snapshot of the robot.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RobotState {
    /// Simulated time (s).
    pub time_s: f64,
    /// Body origin in the world (m).
    pub base_position_m: [f64; 3],
    /// Body orientation, unit quaternion [x, y, z, w].
    pub base_orientation_xyzw: [f64; 4],
    /// Body linear velocity, world frame (m/s).
    pub base_linear_velocity_m_s: [f64; 3],
    /// Body angular velocity, world frame (rad/s).
    pub base_angular_velocity_rad_s: [f64; 3],
    /// Leg joint names, in the order of the arrays below (front, middle, rear; left, right).
    pub joint_names: Vec<String>,
    /// Leg angles (rad, unwrapped; 0 = straight down, positive = turned forward).
    pub joint_positions_rad: Vec<f64>,
    /// Leg speeds (rad/s).
    pub joint_velocities_rad_s: Vec<f64>,
    /// Motor torques commanded in the last step (N m): the PD torque clipped to the motor's
    /// torque-speed limit (rapier does not report multibody motor impulses).
    pub joint_efforts_n_m: Vec<f64>,
    /// Measured phase of tripod A {front-left, middle-right, rear-left} and tripod B
    /// {front-right, middle-left, rear-right}: circular mean of their leg angles, in [0, 2 pi).
    pub tripod_phase_rad: [f64; 2],
}

/// Summary of a run, printed by `sandstep run --json` under `metrics`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RobotMetrics {
    /// Displacement of the body along world +x since the start (m).
    pub distance_m: f64,
    /// `distance_m` over the simulated time (m/s).
    pub mean_speed_m_s: f64,
    /// Body origin at the end (m).
    pub final_position_m: [f64; 3],
    /// Largest angle between the body's up axis and world +z seen at any step (deg).
    pub max_tilt_deg: f64,
    /// Change of heading since the start, counter-clockwise seen from above (deg): where the
    /// body's x axis points at the end. A tripod gait swings it back and forth within each
    /// cycle (by 9 to 19 deg at 4 Hz on sand, `docs/robot.md`), so it is a snapshot.
    pub yaw_change_deg: f64,
    /// Direction of the body's horizontal displacement since the start, counter-clockwise from
    /// world +x seen from above (deg, in (-180, 180]; 0 before the body has moved): where the
    /// robot went, which no within-cycle swing disturbs.
    pub travel_direction_deg: f64,
}

/// The hexapod on rigid ground.
pub struct RobotSim {
    world: PhysicsWorld,
    body: RigidBodyHandle,
    leg_joints: [MultibodyJointHandle; LEG_COUNT],
    leg_bodies: [RigidBodyHandle; LEG_COUNT],
    gait: GaitController,
    motor: DcMotor,
    max_dt_s: f64,
    time_s: f64,
    start_position_m: [f64; 3],
    max_tilt_rad: f64,
    yaw_change_rad: f64,
    last_yaw_rad: f64,
    efforts_n_m: [f64; LEG_COUNT],
    /// Height of the rigid floor (m): `robot.ground.height_m`.
    floor_height_m: f64,
    /// Whether the robot's colliders and the floor take part in collision detection
    /// ([`Self::set_floor_contacts`]).
    floor_contacts: bool,
}

impl RobotSim {
    /// Loads `cfg.urdf`, places the robot at gait phase 0 just above the ground plane z = 0,
    /// and starts the gait of `cfg.gait`. Does not call [`RobotConfig::validate`].
    pub fn new(cfg: &RobotConfig, gravity_m_s2: [f32; 3]) -> Result<Self, RobotError> {
        let urdf = load_urdf(&cfg.urdf)?;
        let mut world = PhysicsWorld::new();
        world.gravity = Vector::new(gravity_m_s2[0], gravity_m_s2[1], gravity_m_s2[2]);
        let params = &mut world.integration_parameters;
        params.dt = cfg.physics.max_dt_s as f32;
        params.num_solver_iterations = cfg.physics.solver_iterations;
        params.length_unit = cfg.physics.length_unit_m as f32;

        let friction = cfg.ground.friction as f32;
        let pose = &cfg.initial_pose;
        let options = UrdfLoaderOptions {
            // Mass properties come from the URDF's <inertial>, not from collider volumes.
            collider_blueprint: ColliderBuilder::default()
                .density(0.0)
                .friction(friction)
                .restitution(RESTITUTION)
                .collision_groups(ROBOT_COLLISION_GROUPS),
            rigid_body_blueprint: RigidBodyBuilder::dynamic().can_sleep(false),
            shift: Pose::from_parts(
                Vec3::new(pose.position_m[0] as f32, pose.position_m[1] as f32, 0.0),
                Quat::from_rotation_z(pose.yaw_deg.to_radians() as f32),
            ),
            ..Default::default()
        };
        let mesh_dir = cfg.urdf.parent().unwrap_or(std::path::Path::new(""));
        let loaded = UrdfRobot::from_robot(&urdf.robot, options, mesh_dir);
        let link_names: Vec<String> = loaded
            .links
            .iter()
            .map(|l| urdf.robot.links[l.urdf_link_index].name.clone())
            .collect();
        let joint_names: Vec<String> = loaded
            .joints
            .iter()
            .map(|j| urdf.robot.joints[j.urdf_joint_index].name.clone())
            .collect();
        let handles = loaded.insert_using_multibody_joints(
            &mut world.bodies,
            &mut world.colliders,
            &mut world.multibody_joints,
            // Legs sweep through each other's planes and the body; the real legs are offset
            // sideways on hubs, so links of the robot do not collide with each other.
            UrdfMultibodyOptions::DISABLE_SELF_CONTACTS,
        );

        let rapier_err = |element: String, message: &str| RobotError::UrdfInvalid {
            path: urdf.path.clone(),
            element,
            message: message.into(),
        };
        let body_index = link_names
            .iter()
            .position(|n| *n == urdf.root_link)
            .ok_or_else(|| {
                rapier_err(
                    format!("link '{}'", urdf.root_link),
                    "not created by the loader",
                )
            })?;
        let body = handles.links[body_index].body;
        let mut leg_joints = Vec::with_capacity(LEG_COUNT);
        let mut leg_bodies = Vec::with_capacity(LEG_COUNT);
        for leg in &LEGS {
            let name = leg.joint_name();
            let j = joint_names
                .iter()
                .position(|n| *n == name)
                .and_then(|i| handles.joints.get(i))
                .ok_or_else(|| {
                    rapier_err(format!("joint '{name}'"), "not created by the loader")
                })?;
            let handle = j.joint.ok_or_else(|| {
                rapier_err(
                    format!("joint '{name}'"),
                    "rapier refused it as a multibody joint",
                )
            })?;
            leg_joints.push(handle);
            leg_bodies.push(j.link2);
        }

        // Rapier gives every angular multibody DOF a default damping of 0.1 N m s/rad "for
        // stability": the stall torque of a leg motor at 1 rad/s. The motors' PD damping and
        // the contacts are all the dissipation this robot has.
        let (mb, _) = world
            .multibody_joints
            .get_mut(leg_joints[0])
            .expect("leg joint");
        mb.damping_mut().fill(MULTIBODY_DOF_DAMPING);

        let command = GaitCommand::from_config(&cfg.gait);
        let mut sim = Self {
            world,
            body,
            leg_joints: leg_joints.try_into().expect("six legs"),
            leg_bodies: leg_bodies.try_into().expect("six legs"),
            gait: GaitController::new(command),
            motor: DcMotor::from(&cfg.gait.motor),
            max_dt_s: cfg.physics.max_dt_s,
            time_s: 0.0,
            start_position_m: [0.0; 3],
            max_tilt_rad: 0.0,
            yaw_change_rad: 0.0,
            last_yaw_rad: 0.0,
            efforts_n_m: [0.0; LEG_COUNT],
            floor_height_m: cfg.ground.height_m,
            floor_contacts: true,
        };
        sim.place_at_phase_zero(pose.clearance_m);
        sim.world.insert(
            RigidBodyBuilder::fixed().translation(Vec3::new(0.0, 0.0, cfg.ground.height_m as f32)),
            ColliderBuilder::new(SharedShape::halfspace(Vector::Z))
                .friction(friction)
                .restitution(RESTITUTION),
        );
        sim.start_position_m = sim.state().base_position_m;
        sim.last_yaw_rad = sim.yaw_rad();
        Ok(sim)
    }

    /// Turns each leg to its gait angle at phase 0 and lifts the robot so that its lowest
    /// collision shape is `clearance_m` above z = 0.
    fn place_at_phase_zero(&mut self, clearance_m: f64) {
        // Forward kinematics reads each link's centre of mass, which rapier otherwise only
        // computes at the first step.
        for h in std::iter::once(self.body).chain(self.leg_bodies) {
            let rb = &mut self.world.bodies[h];
            rb.recompute_mass_properties_from_colliders(&self.world.colliders);
        }
        let angles: Vec<f64> = (0..LEG_COUNT)
            .map(|i| self.gait.target(i).position_rad.unwrap_or(0.0))
            .collect();
        for (i, angle) in angles.iter().enumerate() {
            let (mb, link) = self
                .world
                .multibody_joints
                .get_mut(self.leg_joints[i])
                .expect("leg joint");
            mb.link_mut(link)
                .expect("leg link")
                .joint
                .apply_displacement(&[*angle as f32]);
        }
        self.sync_multibody();
        let lowest_z = self
            .world
            .colliders
            .iter()
            .filter_map(|(_, c)| {
                let parent = self.world.bodies.get(c.parent()?)?;
                let pose = parent.position() * c.position_wrt_parent()?;
                Some(c.shape().compute_aabb(&pose).mins.z)
            })
            .fold(f32::INFINITY, f32::min);
        let mut pose = *self.world.bodies[self.body].position();
        pose.translation.z += clearance_m as f32 - lowest_z;
        self.world.bodies[self.body].set_position(pose, true);
        self.sync_multibody();
    }

    /// Re-runs forward kinematics from the root body's pose and the joint coordinates.
    fn sync_multibody(&mut self) {
        let (mb, _) = self
            .world
            .multibody_joints
            .get_mut(self.leg_joints[0])
            .expect("leg joint");
        mb.forward_kinematics(&self.world.bodies, true);
        mb.update_rigid_bodies(&mut self.world.bodies, true);
    }

    /// Advances by `dt` seconds of simulated time in `ceil(dt / max_dt_s)` equal rapier steps.
    pub fn step(&mut self, dt: f32) {
        let (steps, step_s) = self.equal_steps(dt as f64);
        for _ in 0..steps {
            self.single_step(step_s);
        }
    }

    /// How [`Self::step`] splits `dt_s` seconds: `(count, seconds each)`, equal steps of at
    /// most `max_dt_s`; none for a `dt_s` that is not positive.
    pub fn equal_steps(&self, dt_s: f64) -> (u64, f64) {
        if dt_s.is_nan() || dt_s <= 0.0 {
            return (0, 0.0);
        }
        let steps = (dt_s / self.max_dt_s).ceil().max(1.0);
        (steps as u64, dt_s / steps)
    }

    /// Advances by one rapier step of `dt_s` seconds, whatever `max_dt_s`: for forces computed
    /// for exactly this step (the RFT terrain's implicit terms).
    pub fn single_step(&mut self, dt_s: f64) {
        if self.begin_step(dt_s) {
            self.finish_step(dt_s);
        }
    }

    /// The first half of [`Self::single_step`]: sets rapier's step to `dt_s` and the motors'
    /// targets and torque limits for it, moving nothing, so that a terrain's load computed
    /// next meets the motors as that step will solve them. False (and nothing set) for a step
    /// that is not positive. A step begun and never finished (a stop inside the terrain's
    /// load) leaves the gait advanced and the motors set, the time where it was.
    pub fn begin_step(&mut self, dt_s: f64) -> bool {
        if dt_s.is_nan() || dt_s <= 0.0 {
            return false;
        }
        self.world.integration_parameters.dt = dt_s as f32;
        self.gait.advance(dt_s);
        self.drive_motors();
        true
    }

    /// The second half of [`Self::single_step`]: the rapier step [`Self::begin_step`] set up.
    pub fn finish_step(&mut self, dt_s: f64) {
        self.world.step();
        self.time_s += dt_s;
        self.record_step();
    }

    /// Sets each leg motor's target and torque limit from the gait at the end of this step.
    fn drive_motors(&mut self) {
        let m = self.motor;
        for i in 0..LEG_COUNT {
            let (q, w) = self.joint_position_velocity(i);
            let target = self.gait.target(i);
            let torque = m.pd_torque_n_m(&target, q, w);
            let limit = m.torque_limit_n_m(w, torque);
            self.efforts_n_m[i] = torque.clamp(-limit, limit);
            let (mb, link) = self
                .world
                .multibody_joints
                .get_mut(self.leg_joints[i])
                .expect("leg joint");
            let joint = &mut mb.link_mut(link).expect("leg link").joint.data;
            let (position, stiffness) = match target.position_rad {
                Some(q_t) => (q_t, m.position_gain_n_m_per_rad),
                None => (0.0, 0.0),
            };
            joint
                .set_motor(
                    JointAxis::AngX,
                    position as f32,
                    target.velocity_rad_s as f32,
                    stiffness as f32,
                    m.velocity_gain_n_m_s_per_rad as f32,
                )
                .set_motor_max_force(JointAxis::AngX, limit as f32)
                .set_motor_model(JointAxis::AngX, MotorModel::ForceBased);
        }
    }

    /// Updates the running metrics after a step.
    fn record_step(&mut self) {
        let rot = *self.world.bodies[self.body].rotation();
        let up = rot * Vec3::Z;
        self.max_tilt_rad = self
            .max_tilt_rad
            .max(libm::acos((up.z as f64).clamp(-1.0, 1.0)));
        let yaw = self.yaw_rad();
        self.yaw_change_rad += super::gait::wrap_to_pi(yaw - self.last_yaw_rad);
        self.last_yaw_rad = yaw;
    }

    /// Heading of the body's x axis projected on the ground (rad).
    fn yaw_rad(&self) -> f64 {
        let fwd = *self.world.bodies[self.body].rotation() * Vec3::X;
        libm::atan2(fwd.y as f64, fwd.x as f64)
    }

    /// Angle (rad) and speed (rad/s) of leg `i`.
    fn joint_position_velocity(&self, i: usize) -> (f64, f64) {
        let (mb, link_id) = self
            .world
            .multibody_joints
            .get(self.leg_joints[i])
            .expect("leg joint");
        let link = mb.link(link_id).expect("leg link");
        let q = link.joint().coords()[ANG_X_COORD] as f64;
        let w = mb.joint_velocity(link)[0] as f64;
        (q, w)
    }

    /// Largest rapier step (s): `robot.physics.max_dt_s`.
    pub fn max_dt_s(&self) -> f64 {
        self.max_dt_s
    }

    /// Simulated time (s).
    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    /// Replaces the gait command; takes effect at the next step.
    pub fn command(&mut self, cmd: GaitCommand) {
        let q: [f64; LEG_COUNT] = std::array::from_fn(|i| self.joint_position_velocity(i).0);
        self.gait.set_command(cmd, &q);
    }

    /// The command in force.
    pub fn current_command(&self) -> GaitCommand {
        *self.gait.command()
    }

    /// A snapshot of the robot.
    pub fn state(&self) -> RobotState {
        let rb = &self.world.bodies[self.body];
        let p = rb.translation();
        let r = rb.rotation();
        let (v, w) = (rb.linvel(), rb.angvel());
        let qw: Vec<(f64, f64)> = (0..LEG_COUNT)
            .map(|i| self.joint_position_velocity(i))
            .collect();
        let tripod_phase = |t: Tripod| {
            circular_mean(
                LEGS.iter()
                    .zip(&qw)
                    .filter(|(l, _)| l.tripod == t)
                    .map(|(_, (q, _))| *q),
            )
        };
        RobotState {
            time_s: self.time_s,
            base_position_m: [p.x as f64, p.y as f64, p.z as f64],
            base_orientation_xyzw: [r.x as f64, r.y as f64, r.z as f64, r.w as f64],
            base_linear_velocity_m_s: [v.x as f64, v.y as f64, v.z as f64],
            base_angular_velocity_rad_s: [w.x as f64, w.y as f64, w.z as f64],
            joint_names: LEGS.iter().map(|l| l.joint_name()).collect(),
            joint_positions_rad: qw.iter().map(|(q, _)| *q).collect(),
            joint_velocities_rad_s: qw.iter().map(|(_, w)| *w).collect(),
            joint_efforts_n_m: self.efforts_n_m.to_vec(),
            tripod_phase_rad: [tripod_phase(Tripod::A), tripod_phase(Tripod::B)],
        }
    }

    /// Metrics of the run so far.
    pub fn metrics(&self) -> RobotMetrics {
        let p = self.state().base_position_m;
        let distance_m = p[0] - self.start_position_m[0];
        RobotMetrics {
            distance_m,
            mean_speed_m_s: if self.time_s > 0.0 {
                distance_m / self.time_s
            } else {
                0.0
            },
            final_position_m: p,
            max_tilt_deg: self.max_tilt_rad.to_degrees(),
            yaw_change_deg: self.yaw_change_rad.to_degrees(),
            // + 0.0 turns a sideways displacement of -0.0 into +0.0: straight back is +180.
            travel_direction_deg: libm::atan2(p[1] - self.start_position_m[1] + 0.0, distance_m)
                .to_degrees(),
        }
    }

    /// Total mass of the robot's bodies as rapier sees them (kg).
    pub fn total_mass_kg(&self) -> f64 {
        std::iter::once(self.body)
            .chain(self.leg_bodies)
            .map(|h| self.world.bodies[h].mass() as f64)
            .sum()
    }

    /// The rapier world, for coupling and inspection.
    pub fn world(&self) -> &PhysicsWorld {
        &self.world
    }

    /// Height of the rigid floor (m).
    pub fn floor_height_m(&self) -> f64 {
        self.floor_height_m
    }

    /// Turns the robot's contacts with the rigid floor on (the default) or off: off, rapier
    /// leaves every collider (the robot's and the floor's) out of collision detection, which
    /// is most of a step's cost on RFT ground. Only for terrains that act on the robot
    /// without colliders, while the robot is far from the floor: the robot's links do not
    /// collide with each other, so nothing else is lost. The colliders carry no mass (the
    /// URDF's inertials do), so the robot's dynamics are unchanged.
    pub fn set_floor_contacts(&mut self, enabled: bool) {
        if enabled == self.floor_contacts {
            return;
        }
        for (_, collider) in self.world.colliders.iter_mut() {
            collider.set_enabled(enabled);
        }
        self.floor_contacts = enabled;
    }

    /// The rapier world, mutable (e.g. to add forces from the sand). Multibody links take
    /// external loads as forces (`RigidBody::add_force`), not as velocity changes.
    pub fn world_mut(&mut self) -> &mut PhysicsWorld {
        &mut self.world
    }

    /// The body's rigid body.
    pub fn body_handle(&self) -> RigidBodyHandle {
        self.body
    }

    /// Each leg's rigid body, in [`LEGS`] order.
    pub fn leg_handles(&self) -> [RigidBodyHandle; LEG_COUNT] {
        self.leg_bodies
    }

    /// Commanded phase of tripod A on the left and right side (rad, unwrapped).
    pub fn commanded_phase_rad(&self) -> [f64; 2] {
        self.gait.side_phase_rad()
    }
}
