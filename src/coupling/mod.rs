//! Two-way coupling of the sand ([`crate::mpm`]) with rapier rigid bodies by CPIC
//! (`docs/physics.md`, section 4; Hu et al. 2018).
//!
//! Per substep [`Coupling::substep`]: the solver sorts its particles and allocates its grid;
//! every grid node within [`BAND_CELLS`] of a collider's surface gets its colour (affinity and
//! side bits per collider, distance and normal to the closest one) from the collider's
//! [`CpicSurface`] at the body's current pose; the solver's transfers respect the colours and
//! return the impulse each collider received; two-way colliders get it as a force over the
//! substep, to be applied by the rapier step of the same dt that the caller takes next.

pub mod surface;

use nalgebra::{Matrix3, Vector3};
use rapier3d::glamx::{Mat3, Vec3};
use rapier3d::prelude::{ColliderSet, Pose, RigidBodyHandle, RigidBodySet};
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
    /// Its own mass, as a free body: the more stable, but a leg carrying a load `F` creeps into
    /// the sand at about `F dt / m_leg`, so sinkage and speed follow the step.
    Leg,
    /// The whole robot's inertia, all links as one rigid body: no creep, but a leg pushes the
    /// sand as if its motor could hold any torque, and every leg shape but the C-leg blows up
    /// (`docs/speed-vs-accuracy.md`, "The leg that yields with the robot").
    Robot,
}

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
        &self,
        solver: &mut Solver,
        bodies: &mut RigidBodySet,
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
        let motions: Vec<ColliderMotion> = self
            .colliders
            .iter()
            .map(|c| {
                let rb = &bodies[c.body];
                let yields = c.mode == CouplingMode::TwoWay && rb.is_dynamic();
                ColliderMotion {
                    linear_m_s: to_na(rb.linvel()),
                    angular_rad_s: to_na(rb.angvel()),
                    centre_m: to_na(rb.center_of_mass()),
                    friction: c.friction,
                    yield_inertia: if yields {
                        self.yield_inertia(c.body, bodies)
                    } else {
                        None
                    },
                }
            })
            .collect();
        let impulses = solver.finish_substep(dt, &motions)?;
        self.hand_back(&impulses, bodies, dt);
        Ok(impulses)
    }

    /// The inertia that yields with `body` within a substep, about its centre of mass: its
    /// group's, as one rigid body, or its own (isotropic, its smallest principal moment, which
    /// errs on the yielding side). None if a body of its group is not dynamic (held in place).
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
            let rotation = to_na_matrix(Mat3::from_quat(*member.rotation()));
            let local = to_na_matrix(
                member
                    .mass_properties()
                    .local_mprops
                    .reconstruct_inertia_matrix(),
            );
            (
                member.mass() as f64,
                to_na(member.center_of_mass()).cast::<f64>(),
                rotation * local * rotation.transpose(),
            )
        });
        Some(YieldInertia::of_parts(
            parts,
            &to_na(rb.center_of_mass()).cast::<f64>(),
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

/// A rapier 3x3 matrix in f64 nalgebra.
fn to_na_matrix(m: Mat3) -> Matrix3<f64> {
    Matrix3::from_fn(|r, c| m.col(c)[r] as f64)
}

fn to_na(v: Vec3) -> Vector3<f32> {
    Vector3::new(v.x, v.y, v.z)
}
