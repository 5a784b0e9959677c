//! Two-way coupling of the sand ([`crate::mpm`]) with rapier rigid bodies by CPIC
//! (`docs/physics.md`, section 4; Hu et al. 2018).
//!
//! Per substep [`Coupling::substep`]: the solver sorts its particles and allocates its grid;
//! every grid node within [`BAND_CELLS`] of a collider's surface gets its colour (affinity and
//! side bits per collider, distance and normal to the closest one) from the collider's
//! [`CpicSurface`] at the body's current pose; the solver's transfers respect the colours and
//! return the impulse each collider received; two-way colliders get it as a force over the
//! substep, to be applied by the rapier step of the same dt that the caller takes next.

pub mod articulated;
pub mod surface;

use nalgebra::{Matrix3, Vector3};
use rapier3d::glamx::{Mat3, Vec3};
use rapier3d::prelude::{
    ColliderSet, MultibodyJointSet, Pose, RigidBody, RigidBodyHandle, RigidBodySet,
};
use serde::{Deserialize, Serialize};

use crate::mpm::cpic::{
    ColliderImpulse, ColliderMotion, ColourBlock, NodeColour, YieldInertia, MAX_COLLIDERS,
};
use crate::mpm::grid::{node_in_block, BLOCK_EDGE};
use crate::mpm::sleep::WakeZone;
use crate::mpm::{SimError, Solver};
pub use surface::{CpicSurface, SurfaceError, SurfaceSample};

/// Half-width of the narrow band around each collider in which grid nodes are coloured, in grid
/// cells: the reach of the quadratic B-spline stencil.
pub const BAND_CELLS: f32 = 1.5;
/// A collider surface may move at most this many grid cells per substep (the colours are
/// computed once per substep at its start).
pub const MAX_CELLS_PER_SUBSTEP: f32 = 0.1;

/// How a collider takes part in the sand's dynamics.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum CouplingMode {
    /// The sand does not see it.
    None,
    /// The sand feels the body, the body not the sand (kinematic bodies, probes).
    OneWay,
    /// Both feel each other.
    TwoWay,
}

/// How colliders act on the sand.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum CouplingMethod {
    /// Compatible particle-in-cell: thin colliders neither leak sand nor go unfelt.
    Cpic,
    /// The plain grid-boundary treatment, for comparison only: grid nodes inside a collider take
    /// its velocity. Colliders thinner than a cell let sand through; no impulses are returned.
    GridBoundary,
}

/// What a robot's leg yields to the sand with within a substep (CPIC's light-body yield,
/// `docs/physics.md` CPIC step 7).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum LegYield {
    /// Its own mass, as a free body (kept for comparison): a leg carrying a load `F` creeps
    /// into the sand at about `F dt / m_leg`, so sinkage and speed follow the step.
    Leg,
    /// The whole robot's inertia, all links as one rigid body (kept for comparison): a leg
    /// pushes the sand as if its motor could hold any torque (`docs/speed-vs-accuracy.md`,
    /// "The leg that yields with the robot").
    Robot,
    /// The inertia the robot's multibody presents at the leg, its joints free
    /// ([`articulated::operational_space_inertia`]): the robot's along the directions the hip
    /// holds, the leg's own about the hinge. The scenes' default; with the load predicted
    /// ([`LoadPrediction::LastSubstep`]) the C-leg robot no longer creeps
    /// (`docs/speed-vs-accuracy.md`, "The leg that yields as its multibody presents it").
    Articulated,
}

/// What CPIC's yield (`docs/physics.md` CPIC step 7) takes for a body's velocity over the
/// substep.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum LoadPrediction {
    /// Its velocity at the start of the substep. The loads the body gets from elsewhere over
    /// the substep (gravity, joints, motors) reach the sand one substep late, so a body carrying
    /// a load `F` creeps through the sand at about `F dt / M_b`.
    None,
    /// That velocity plus the change every load but the sand's on this body gives it over the
    /// substep (gravity, joints, motors, and the sand's pushes on the other links of its
    /// multibody, a substep late), as measured over the last substep: its velocity change less
    /// the sand's impulse over the inertia its dynamics present, scaled to this substep's
    /// length. Sound only where the yielding inertia is that inertia too: a multibody link with
    /// [`LegYield::Articulated`] (a leg yielding with its own 2 g while the robot carries it
    /// turns the estimate into a stiff spring, and the robot goes wild); a free body, though it
    /// yields isotropically with its smallest moment, which makes its spin estimate a soft
    /// spring. Bodies whose response is not known (multibody links without articulation,
    /// rigid groups) get no prediction.
    LastSubstep,
}

/// One two-way body's last substep, for [`LoadPrediction::LastSubstep`].
#[derive(Clone, Copy, Debug)]
struct BodyHistory {
    body: RigidBodyHandle,
    /// Velocity of the centre of mass (m/s) and angular velocity (rad/s) at its start.
    start_velocity: (Vec3, Vec3),
    /// The sand's impulse (N s, N m s about the centre of mass) handed to it.
    sand_impulse: (Vector3<f64>, Vector3<f64>),
    /// Its length (s).
    dt_s: f32,
    /// Acceleration (m/s^2, rad/s^2) from every load but the sand's, as last estimated.
    load_rate: Option<(Vec3, Vec3)>,
}

/// A substep shorter than this fraction of the next one does not update the load estimate.
const MIN_ESTIMATING_STEP_FRACTION: f32 = 0.5;

/// One rigid collider as the sand sees it.
#[derive(Clone, Debug)]
pub struct SandCollider {
    /// For messages.
    pub name: String,
    /// The rapier body it moves with.
    pub body: RigidBodyHandle,
    /// Pose of the surface in the body's frame.
    pub body_to_surface: Pose,
    pub surface: CpicSurface,
    /// Coulomb friction coefficient sand-on-collider (dimensionless).
    pub friction: f32,
    pub mode: CouplingMode,
}

/// Errors building a coupling.
#[derive(thiserror::Error, Debug, Clone, PartialEq)]
pub enum CouplingError {
    #[error("{count} colliders are coupled to the sand; CPIC tells at most {MAX_COLLIDERS} apart")]
    TooManyColliders { count: usize },
    #[error("collider {name}: its body is not in the rapier world")]
    MissingBody { name: String },
    #[error("rigid group: body {body} is not in the rapier world")]
    GroupBodyMissing { body: String },
    #[error("rigid group: body {body} is already in another group")]
    GroupOverlap { body: String },
    #[error("{name}: cannot make its sand surface: {source}")]
    Surface { name: String, source: SurfaceError },
}

/// The colliders coupled to one sand solver.
pub struct Coupling {
    /// Colliders with a mode other than `None`, in colour-bit order.
    colliders: Vec<SandCollider>,
    method: CouplingMethod,
    /// Bodies that joints and motors hold together within a substep (a robot's links): a
    /// collider on one of them yields to the sand with the whole group's inertia.
    rigid_groups: Vec<Vec<RigidBodyHandle>>,
    load_prediction: LoadPrediction,
    /// Multibody links yield with the inertia their multibody presents at them.
    articulated: bool,
    /// With articulation, the motors' impedance over the step joins it: rapier's solver
    /// substeps per step ([`Self::with_motor_impedance`]).
    motor_substeps: Option<usize>,
    /// The two-way bodies' last substep (with [`LoadPrediction::LastSubstep`]).
    history: Vec<BodyHistory>,
}

/// A collider at the start of a substep.
struct Placed<'a> {
    collider: &'a SandCollider,
    /// World pose of the surface.
    pose: Pose,
    /// World bounding box of the surface grown by the band (m).
    min: Vector3<f32>,
    max: Vector3<f32>,
}

impl Coupling {
    /// Couples the colliders whose mode is not `None`.
    pub fn new(colliders: Vec<SandCollider>, bodies: &RigidBodySet) -> Result<Self, CouplingError> {
        let colliders: Vec<SandCollider> = colliders
            .into_iter()
            .filter(|c| c.mode != CouplingMode::None)
            .collect();
        if colliders.len() > MAX_COLLIDERS {
            return Err(CouplingError::TooManyColliders {
                count: colliders.len(),
            });
        }
        if let Some(c) = colliders.iter().find(|c| bodies.get(c.body).is_none()) {
            return Err(CouplingError::MissingBody {
                name: c.name.clone(),
            });
        }
        Ok(Coupling {
            colliders,
            method: CouplingMethod::Cpic,
            rigid_groups: Vec::new(),
            load_prediction: LoadPrediction::None,
            history: Vec::new(),
            articulated: false,
            motor_substeps: None,
        })
    }

    /// The same colliders, with `group` held together within a substep: a two-way collider on
    /// any of its bodies yields to the sand as one rigid body with all their mass and inertia,
    /// as a robot's leg does whose motor holds it to the body (`docs/physics.md`, CPIC step 7).
    /// A body in no group yields alone. Every body must be in `bodies` and in one group at most.
    pub fn with_rigid_group(
        mut self,
        group: Vec<RigidBodyHandle>,
        bodies: &RigidBodySet,
    ) -> Result<Self, CouplingError> {
        if let Some(&h) = group.iter().find(|&&h| bodies.get(h).is_none()) {
            return Err(CouplingError::GroupBodyMissing {
                body: format!("{h:?}"),
            });
        }
        if let Some(&h) = group
            .iter()
            .find(|&&h| self.rigid_groups.iter().any(|g| g.contains(&h)))
        {
            return Err(CouplingError::GroupOverlap {
                body: format!("{h:?}"),
            });
        }
        self.rigid_groups.push(group);
        Ok(self)
    }

    /// The same colliders, with the yield taking the bodies' velocities as `prediction` says.
    pub fn with_load_prediction(self, prediction: LoadPrediction) -> Self {
        Coupling {
            load_prediction: prediction,
            history: Vec::new(),
            ..self
        }
    }

    /// The same colliders, with a two-way collider on a multibody link yielding with the inertia
    /// the multibody presents at the link ([`articulated::operational_space_inertia`]; the
    /// multibody joints must then be given to [`Self::substep_with_joints`]).
    pub fn with_articulation(self) -> Self {
        Coupling {
            articulated: true,
            ..self
        }
    }

    /// The same colliders, with an articulated link also yielding with the impedance its
    /// multibody's motors present over the step ([`articulated::motor_impedances`]; rapier
    /// solves the step in `solver_substeps` substeps).
    pub fn with_motor_impedance(self, solver_substeps: usize) -> Self {
        Coupling {
            motor_substeps: Some(solver_substeps),
            ..self
        }
    }

    /// The same colliders acting by another method.
    pub fn with_method(self, method: CouplingMethod) -> Self {
        Coupling { method, ..self }
    }

    /// The coupled colliders, in colour-bit order (the order of the impulses).
    pub fn colliders(&self) -> &[SandCollider] {
        &self.colliders
    }

    /// Longest step (s) that keeps every collider surface within [`MAX_CELLS_PER_SUBSTEP`] of
    /// where its colours were computed: `inf` for colliders at rest.
    pub fn max_dt_s(&self, bodies: &RigidBodySet, dx: f32) -> f32 {
        let fastest = self
            .colliders
            .iter()
            .map(|c| {
                let rb = &bodies[c.body];
                let (min, max) = c.surface.local_aabb();
                let half_diagonal = 0.5 * (Vec3::from(max) - Vec3::from(min)).length();
                let box_centre = (*rb.position() * c.body_to_surface)
                    .transform_point((Vec3::from(min) + Vec3::from(max)) * 0.5);
                let centre_offset = (box_centre - rb.center_of_mass()).length();
                let reach = if half_diagonal.is_finite() {
                    half_diagonal + centre_offset
                } else {
                    0.0
                };
                rb.linvel().length() + rb.angvel().length() * reach
            })
            .fold(0.0f32, f32::max);
        MAX_CELLS_PER_SUBSTEP * dx / fastest
    }

    /// One coupled sand substep of `dt` seconds against the bodies' current poses and
    /// velocities. Two-way bodies get the sand's impulse as a force and torque over `dt` (their
    /// previous user forces are replaced), so the caller must step rapier by the same `dt` next.
    /// Returns the impulse each coupled collider received (N s, N m s about its body's centre of
    /// mass), one-way colliders included.
    pub fn substep(
        &mut self,
        solver: &mut Solver,
        bodies: &mut RigidBodySet,
        dt: f32,
    ) -> Result<Vec<ColliderImpulse>, SimError> {
        self.substep_with_joints(solver, bodies, None, dt)
    }

    /// [`Self::substep`] for bodies that may be multibody links (`joints`).
    pub fn substep_with_joints(
        &mut self,
        solver: &mut Solver,
        bodies: &mut RigidBodySet,
        joints: Option<&MultibodyJointSet>,
        dt: f32,
    ) -> Result<Vec<ColliderImpulse>, SimError> {
        let dx = solver.grid().dx;
        let origin = solver.grid().origin;
        let band = BAND_CELLS * dx;
        let placed: Vec<Placed> = self
            .colliders
            .iter()
            .map(|c| {
                let pose = *bodies[c.body].position() * c.body_to_surface;
                let (min, max) = world_aabb(&pose, c.surface.local_aabb());
                Placed {
                    collider: c,
                    pose,
                    min: min.add_scalar(-band),
                    max: max.add_scalar(band),
                }
            })
            .collect();
        let wake_zones: Vec<WakeZone> = placed.iter().map(|p| [p.min, p.max]).collect();
        solver.begin_substep(&wake_zones);
        let method = self.method;
        solver.colour_nodes(|block| colour_block(block, &placed, method, origin, dx, band));
        // The inertia each multibody link presents, computed once per collider and substep.
        let articulated: Vec<Option<YieldInertia>> = self
            .colliders
            .iter()
            .map(|c| {
                joints.filter(|_| self.articulated).and_then(|j| {
                    let motors = self.motor_substeps.map(|n| (dt, n));
                    articulated::operational_space_inertia(j, c.body, motors)
                })
            })
            .collect();
        let yield_inertias: Vec<Option<YieldInertia>> = self
            .colliders
            .iter()
            .zip(&articulated)
            .map(|(c, &articulated)| {
                let yields = c.mode == CouplingMode::TwoWay && bodies[c.body].is_dynamic();
                yields
                    .then(|| articulated.or_else(|| self.yield_inertia(c.body, bodies)))
                    .flatten()
            })
            .collect();
        let velocities: Vec<(Vec3, Vec3)> = self
            .colliders
            .iter()
            .map(|c| self.body_velocity(c.body, bodies, joints))
            .collect();
        if self.load_prediction == LoadPrediction::LastSubstep {
            let response_inertias: Vec<Option<YieldInertia>> = self
                .colliders
                .iter()
                .zip(&articulated)
                .map(|(c, &articulated)| self.response_inertia(c.body, bodies, joints, articulated))
                .collect();
            self.estimate_load_rates(&velocities, &response_inertias, dt);
        }
        let motions: Vec<ColliderMotion> = self
            .colliders
            .iter()
            .zip(&yield_inertias)
            .zip(&velocities)
            .map(|((c, &yield_inertia), &(linvel, angvel))| {
                let rb = &bodies[c.body];
                let (load_kick_m_s, load_kick_rad_s) = match self.load_rate(c.body) {
                    Some((linear, angular)) if yield_inertia.is_some() => {
                        (to_na(linear * dt), to_na(angular * dt))
                    }
                    _ => Default::default(),
                };
                ColliderMotion {
                    linear_m_s: to_na(linvel),
                    angular_rad_s: to_na(angvel),
                    centre_m: to_na(rb.center_of_mass()),
                    friction: c.friction,
                    yield_inertia,
                    load_kick_m_s,
                    load_kick_rad_s,
                }
            })
            .collect();
        let impulses = solver.finish_substep(dt, &motions)?;
        self.remember(&impulses, &velocities, dt);
        self.hand_back(&impulses, bodies, dt);
        Ok(impulses)
    }

    /// The velocity of `body`'s centre of mass (m/s) and its angular velocity (rad/s): for a
    /// multibody link with articulation on, from the multibody's generalized velocities
    /// ([`articulated::link_velocity`]), else its rigid-body velocity.
    fn body_velocity(
        &self,
        body: RigidBodyHandle,
        bodies: &RigidBodySet,
        joints: Option<&MultibodyJointSet>,
    ) -> (Vec3, Vec3) {
        joints
            .filter(|_| self.articulated)
            .and_then(|j| articulated::link_velocity(j, body))
            .unwrap_or_else(|| (bodies[body].linvel(), bodies[body].angvel()))
    }

    /// The acceleration (m/s^2, rad/s^2) of `body` from every load but the sand's, as last
    /// estimated (`LoadPrediction::LastSubstep`).
    fn load_rate(&self, body: RigidBodyHandle) -> Option<(Vec3, Vec3)> {
        self.history
            .iter()
            .find(|h| h.body == body)
            .and_then(|h| h.load_rate)
    }

    /// Updates each two-way body's load acceleration from its last substep: its velocity
    /// change less what the sand's impulse on it gave its response inertia (`response_inertias`,
    /// per collider, [`Self::response_inertia`]), over the substep's length. None where the
    /// response inertia is not known. A last substep much shorter than the coming one `dt` (the
    /// sliver that ends a frame) measures too little to scale up, so the previous estimate
    /// stands. Assumes one rigid-body step of the substep's length between two substeps: any
    /// other change of a body's velocity counts as load.
    fn estimate_load_rates(
        &mut self,
        velocities: &[(Vec3, Vec3)],
        response_inertias: &[Option<YieldInertia>],
        dt: f32,
    ) {
        for h in self.history.iter_mut() {
            if h.dt_s < MIN_ESTIMATING_STEP_FRACTION * dt {
                continue;
            }
            let Some((inertia, (linvel, angvel))) = self
                .colliders
                .iter()
                .zip(response_inertias.iter().zip(velocities))
                .find_map(|(c, (y, v))| y.filter(|_| c.body == h.body).map(|y| (y, *v)))
            else {
                h.load_rate = None;
                continue;
            };
            let Some((sand_linear, sand_angular)) =
                inertia.velocity_change(&h.sand_impulse.0, &h.sand_impulse.1)
            else {
                h.load_rate = None;
                continue;
            };
            let to_vec3 = |v: Vector3<f64>| Vec3::new(v.x as f32, v.y as f32, v.z as f32);
            let linear = (linvel - h.start_velocity.0 - to_vec3(sand_linear)) / h.dt_s;
            let angular = (angvel - h.start_velocity.1 - to_vec3(sand_angular)) / h.dt_s;
            h.load_rate = (linear.is_finite() && angular.is_finite()).then_some((linear, angular));
        }
    }

    /// Records each two-way body's velocity at the start of this substep, the sand's impulse on
    /// it over the substep and the substep's length (`LoadPrediction::LastSubstep`).
    fn remember(&mut self, impulses: &[ColliderImpulse], velocities: &[(Vec3, Vec3)], dt: f32) {
        if self.load_prediction != LoadPrediction::LastSubstep {
            return;
        }
        for h in self.history.iter_mut() {
            h.sand_impulse = (Vector3::zeros(), Vector3::zeros());
        }
        for ((c, j), &start_velocity) in self.colliders.iter().zip(impulses).zip(velocities) {
            if c.mode != CouplingMode::TwoWay {
                continue;
            }
            let index = match self.history.iter().position(|h| h.body == c.body) {
                Some(i) => i,
                None => {
                    self.history.push(BodyHistory {
                        body: c.body,
                        start_velocity,
                        sand_impulse: (Vector3::zeros(), Vector3::zeros()),
                        dt_s: dt,
                        load_rate: None,
                    });
                    self.history.len() - 1
                }
            };
            let h = &mut self.history[index];
            h.start_velocity = start_velocity;
            h.dt_s = dt;
            h.sand_impulse.0 += j.linear_n_s;
            h.sand_impulse.1 += j.angular_n_m_s;
        }
    }

    /// The inertia that yields with `body` within a substep, about its centre of mass, where
    /// it is no articulated link: its group's, as one rigid body, or its own (isotropic, its
    /// smallest principal moment, which errs on the yielding side). None if a body of its
    /// group is not dynamic (held in place).
    fn yield_inertia(&self, body: RigidBodyHandle, bodies: &RigidBodySet) -> Option<YieldInertia> {
        let rb = &bodies[body];
        let Some(group) = self.rigid_groups.iter().find(|g| g.contains(&body)) else {
            let smallest = rb
                .mass_properties()
                .local_mprops
                .principal_inertia()
                .min_element();
            return Some(YieldInertia::free_body(rb.mass() as f64, smallest as f64));
        };
        if !group
            .iter()
            .all(|&h| bodies.get(h).is_some_and(|b| b.is_dynamic()))
        {
            return None;
        }
        let parts = group.iter().map(|&h| {
            let member = &bodies[h];
            (
                member.mass() as f64,
                to_na(member.center_of_mass()).cast::<f64>(),
                world_inertia(member),
            )
        });
        Some(YieldInertia::of_parts(
            parts,
            &to_na(rb.center_of_mass()).cast::<f64>(),
        ))
    }

    /// The inertia with which `body`'s dynamics answer an impulse on it alone, about its centre
    /// of mass, for [`LoadPrediction::LastSubstep`]: for a multibody link, the inertia its
    /// multibody presents at it (`articulated`, known only with articulation); a free body's
    /// own full inertia tensor. None where it is not known: a multibody link without
    /// articulation, a body of a rigid group (the group is a lock the exchange assumes, not the
    /// body's dynamics); such a body gets no prediction.
    fn response_inertia(
        &self,
        body: RigidBodyHandle,
        bodies: &RigidBodySet,
        joints: Option<&MultibodyJointSet>,
        articulated: Option<YieldInertia>,
    ) -> Option<YieldInertia> {
        if joints.is_some_and(|j| j.rigid_body_link(body).is_some()) {
            return articulated;
        }
        if self.rigid_groups.iter().any(|g| g.contains(&body)) {
            return None;
        }
        let rb = &bodies[body];
        Some(YieldInertia::rigid(
            rb.mass() as f64,
            &Vector3::zeros(),
            &world_inertia(rb),
        ))
    }

    /// Applies the two-way colliders' impulses as forces and torques over `dt`, summed per body.
    fn hand_back(&self, impulses: &[ColliderImpulse], bodies: &mut RigidBodySet, dt: f32) {
        let two_way = || {
            self.colliders
                .iter()
                .zip(impulses)
                .filter(|(c, _)| c.mode == CouplingMode::TwoWay)
        };
        for (c, _) in two_way() {
            let rb = &mut bodies[c.body];
            rb.reset_forces(false);
            rb.reset_torques(false);
        }
        for (c, j) in two_way() {
            let rb = &mut bodies[c.body];
            let to_force = |v: Vector3<f64>| Vec3::new(v.x as f32, v.y as f32, v.z as f32) / dt;
            rb.add_force(to_force(j.linear_n_s), true);
            rb.add_torque(to_force(j.angular_n_m_s), true);
        }
    }
}

/// How the sand sees the colliders of one rapier body, each as `(pose in the body frame,
/// surface)`: cuboids thinner than `thin_m` are parts the grid cannot resolve, so all of them
/// together become one sheet through their mid-planes (they must form a chain, end to end, like
/// a leg's collision boxes); every other collider is a solid of its own shape.
pub fn body_surfaces(
    body: RigidBodyHandle,
    bodies: &RigidBodySet,
    colliders: &ColliderSet,
    thin_m: f32,
) -> Result<Vec<(Pose, CpicSurface)>, SurfaceError> {
    let rb = bodies.get(body).ok_or(SurfaceError::MissingBody)?;
    let mut chain = Vec::new();
    let mut surfaces = Vec::new();
    for &handle in rb.colliders() {
        let c = &colliders[handle];
        let pose = c.position_wrt_parent().copied().unwrap_or(Pose::IDENTITY);
        match c.shape().as_cuboid() {
            Some(cuboid) if 2.0 * cuboid.half_extents.min_element() < thin_m => {
                chain.push((pose, cuboid.half_extents));
            }
            _ => surfaces.push((pose, CpicSurface::Solid(c.shared_shape().clone()))),
        }
    }
    if !chain.is_empty() {
        surfaces.push((Pose::IDENTITY, box_chain_sheet(&chain)?));
    }
    Ok(surfaces)
}

/// One sheet through the mid-planes of thin boxes `(pose, half extents)` laid end to end, in
/// order: a strip whose cross-lines sit at the chain's ends and halfway between neighbouring box
/// ends. The box axis closest to the line to its neighbour runs along the chain; of the other
/// two, the longer is the width, the shorter the thickness. (Not by size alone: the boxes of a
/// straight or slightly curved leg are shorter along the chain than the leg is thick.) A chain
/// of one box runs along its longest axis, across its middle one.
pub fn box_chain_sheet(boxes: &[(Pose, Vec3)]) -> Result<CpicSurface, SurfaceError> {
    if boxes.is_empty() {
        return Err(SurfaceError::NoBoxes);
    }
    let centre = |i: usize| boxes[i].0.translation;
    // Direction of the chain at box i: towards the next box (from the previous for the last).
    let forward = |i: usize| match boxes.len() {
        1 => None,
        n if i + 1 < n => Some(centre(i + 1) - centre(i)),
        _ => Some(centre(i) - centre(i - 1)),
    };
    // (centre, half-length vector pointing forward, half-width vector, all on one side)
    let mut parts: Vec<(Vec3, Vec3, Vec3)> = Vec::with_capacity(boxes.len());
    for (i, (pose, half)) in boxes.iter().enumerate() {
        let h = half.to_array();
        let mut order = [0, 1, 2];
        order.sort_by(|&a, &b| h[a].total_cmp(&h[b]));
        let axis = |k: usize| pose.rotation * Vec3::AXES[order[k]] * h[order[k]];
        let dir = forward(i).unwrap_or(axis(2));
        // The axis closest to the chain's direction (by the cosine), then the longer of the
        // other two (`order` is by size).
        let alignment = |k: usize| (pose.rotation * Vec3::AXES[order[k]]).dot(dir).abs();
        let k_along = (0..3)
            .rev()
            .max_by(|&a, &b| alignment(a).total_cmp(&alignment(b)))
            .expect("three axes");
        let k_across = if k_along == 2 { 1 } else { 2 };
        let (along, across) = (axis(k_along), axis(k_across));
        let along = if along.dot(dir) < 0.0 { -along } else { along };
        let across = match parts.last() {
            Some((_, _, previous)) if across.dot(*previous) < 0.0 => -across,
            _ => across,
        };
        parts.push((pose.translation, along, across));
    }
    let (first, along, across) = parts[0];
    let mut stations = vec![(first - along, across)];
    for pair in parts.windows(2) {
        let ((c0, l0, w0), (c1, l1, w1)) = (pair[0], pair[1]);
        let (end, start) = (c0 + l0, c1 - l1);
        if end.distance(start) > 0.5 * l0.length().min(l1.length()) {
            return Err(SurfaceError::NotAChain {
                end_m: end.to_array(),
                start_m: start.to_array(),
            });
        }
        stations.push(((end + start) * 0.5, (w0 + w1) * 0.5));
    }
    let (last, along, across) = parts[parts.len() - 1];
    stations.push((last + along, across));
    let mut vertices = Vec::with_capacity(2 * stations.len());
    for (centre, across) in &stations {
        vertices.push((*centre - *across).to_array());
        vertices.push((*centre + *across).to_array());
    }
    let triangles = (0..stations.len() as u32 - 1)
        .flat_map(|j| {
            [
                [2 * j, 2 * j + 2, 2 * j + 1],
                [2 * j + 1, 2 * j + 2, 2 * j + 3],
            ]
        })
        .collect();
    CpicSurface::sheet(vertices, triangles)
}

/// Colours of the 64 nodes of grid block `block`, or None if no collider's band reaches them.
fn colour_block(
    block: [i32; 3],
    placed: &[Placed],
    method: CouplingMethod,
    origin: Vector3<f32>,
    dx: f32,
    band: f32,
) -> Option<ColourBlock> {
    let first = Vector3::from(block.map(|b| (b * BLOCK_EDGE) as f32)) * dx + origin;
    let last = first.add_scalar((BLOCK_EDGE - 1) as f32 * dx);
    let near: Vec<(usize, &Placed)> = placed
        .iter()
        .enumerate()
        .filter(|(_, p)| (0..3).all(|a| p.min[a] <= last[a] && first[a] <= p.max[a]))
        .collect();
    if near.is_empty() {
        return None;
    }
    let mut colours = [NodeColour::default(); BLOCK_EDGE.pow(3) as usize];
    let mut any = false;
    let edge = BLOCK_EDGE as usize;
    for (x, y, z) in
        (0..edge).flat_map(|x| (0..edge).flat_map(move |y| (0..edge).map(move |z| (x, y, z))))
    {
        let point = first + Vector3::new(x as f32, y as f32, z as f32) * dx;
        let colour = &mut colours[node_in_block(x, y, z)];
        let mut closest = f32::INFINITY;
        for &(r, p) in &near {
            let Some(s) = p.collider.surface.sample(&p.pose, point.into(), band) else {
                continue;
            };
            if method == CouplingMethod::GridBoundary {
                if s.signed_distance_m <= 0.0 {
                    colour.imposed = r as u8 + 1;
                    any = true;
                }
                continue;
            }
            if !s.affinity {
                continue;
            }
            colour.set(r, s.positive_side);
            if s.distance_m < closest {
                closest = s.distance_m;
                colour.closest = r as u8;
                colour.signed_distance_m = s.signed_distance_m;
                colour.normal = s.normal;
            }
            any = true;
        }
    }
    any.then_some(colours)
}

/// World bounding box of a local box under `pose`.
fn world_aabb(pose: &Pose, (min, max): ([f32; 3], [f32; 3])) -> (Vector3<f32>, Vector3<f32>) {
    let mut lo = Vector3::repeat(f32::INFINITY);
    let mut hi = Vector3::repeat(f32::NEG_INFINITY);
    for corner in 0..8 {
        let pick = |a: usize| if corner >> a & 1 == 0 { min[a] } else { max[a] };
        let local = Vec3::new(pick(0), pick(1), pick(2));
        let w = to_na(pose.transform_point(local));
        lo = lo.inf(&w);
        hi = hi.sup(&w);
    }
    // An unbounded local box (the half-space) stays unbounded.
    for a in 0..3 {
        if !min[a].is_finite() || !max[a].is_finite() || !lo[a].is_finite() || !hi[a].is_finite() {
            lo[a] = f32::NEG_INFINITY;
            hi[a] = f32::INFINITY;
        }
    }
    (lo, hi)
}

/// A body's inertia tensor about its centre of mass in world axes (kg m^2).
fn world_inertia(rb: &RigidBody) -> Matrix3<f64> {
    let rotation = to_na_matrix(Mat3::from_quat(*rb.rotation()));
    let local = to_na_matrix(
        rb.mass_properties()
            .local_mprops
            .reconstruct_inertia_matrix(),
    );
    rotation * local * rotation.transpose()
}

/// A rapier 3x3 matrix in f64 nalgebra.
fn to_na_matrix(m: Mat3) -> Matrix3<f64> {
    Matrix3::from_fn(|r, c| m.col(c)[r] as f64)
}

fn to_na(v: Vec3) -> Vector3<f32> {
    Vector3::new(v.x, v.y, v.z)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rapier3d::prelude::{MassProperties, RigidBodyBuilder, SharedShape};

    /// A steel ball coupled both ways, with the load predicted.
    fn predicted_ball() -> (Coupling, RigidBodySet, RigidBodyHandle) {
        let mut bodies = RigidBodySet::new();
        // Steel, 1 cm radius: 33 g.
        let handle = bodies.insert(
            RigidBodyBuilder::dynamic()
                .additional_mass_properties(MassProperties::from_ball(7800.0, 0.01)),
        );
        bodies[handle].recompute_mass_properties_from_colliders(&ColliderSet::new());
        let collider = SandCollider {
            name: "ball".into(),
            body: handle,
            body_to_surface: Pose::IDENTITY,
            surface: CpicSurface::Solid(SharedShape::ball(0.01)),
            friction: 0.3,
            mode: CouplingMode::TwoWay,
        };
        let coupling = Coupling::new(vec![collider], &bodies)
            .unwrap()
            .with_load_prediction(LoadPrediction::LastSubstep);
        (coupling, bodies, handle)
    }

    /// A body that fell freely by `g dt` while the sand pushed it up by `J / m` carried a
    /// load of `g`: the sand's share is taken out. A sliver of a step after it keeps that
    /// estimate however noisy its own change.
    #[test]
    fn the_load_is_the_velocity_change_less_the_sand() {
        let (mut coupling, bodies, ball) = predicted_ball();
        let (dt, g, push) = (1e-4f32, Vec3::new(0.0, 0.0, -9.81), 2e-6f64);
        let start = (Vec3::new(0.1, 0.0, 0.0), Vec3::ZERO);
        let sand = ColliderImpulse {
            linear_n_s: Vector3::new(0.0, 0.0, push),
            ..Default::default()
        };
        coupling.remember(&[sand], &[start], dt);
        let mass = bodies[ball].mass();
        let now = start.0 + g * dt + Vec3::new(0.0, 0.0, push as f32 / mass);
        let response = [coupling.response_inertia(ball, &bodies, None, None)];
        coupling.estimate_load_rates(&[(now, Vec3::ZERO)], &response, dt);
        let (linear, angular) = coupling.load_rate(ball).expect("estimated");
        assert!((linear - g).length() < 1e-3, "{linear:?}");
        assert!(angular.length() < 1e-6, "{angular:?}");
        // A sliver: its change says nothing about the load.
        coupling.remember(
            &[ColliderImpulse::default()],
            &[(now, Vec3::ZERO)],
            0.1 * dt,
        );
        let noisy = (now + Vec3::new(0.3, 0.0, 0.0), Vec3::ZERO);
        coupling.estimate_load_rates(&[noisy], &response, dt);
        let kept = coupling.load_rate(ball).expect("kept").0;
        assert!((kept - g).length() < 1e-3, "{kept:?}");
    }

    /// Without articulation a multibody link's response is not known, nor a rigid group's:
    /// no prediction for them.
    #[test]
    fn no_prediction_where_the_response_is_unknown() {
        let (coupling, bodies, ball) = predicted_ball();
        let grouped = coupling.with_rigid_group(vec![ball], &bodies).unwrap();
        assert!(grouped
            .response_inertia(ball, &bodies, None, None)
            .is_none());
    }
}
