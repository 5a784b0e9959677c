//! Resistive force theory (RFT): the granular terrain as a local, rate-independent stress on
//! every surface element of a body moving through it (Li, Zhang and Goldman, "A terradynamics
//! of legged locomotion on granular media", Science 339:1408, 2013; `docs/physics.md`,
//! "Resistive force theory").
//!
//! **2D law.** An element of area `dA` at depth `|z|` below the free surface, moving in a
//! vertical plane, feels `dF_x = alpha_x(beta, gamma) |z| dA` and `dF_z = alpha_z(beta, gamma)
//! |z| dA` (nothing above the surface). The medium's stress law `alpha` ([`super::stress_law`],
//! `RftParams::law`) is Li et al.'s generic form (their Eq. 1 and the generic coefficients of
//! their supplement) scaled by `zeta = alpha_z(0, pi/2)`, the stress per unit depth under a
//! horizontal plate pressed straight down; or the stress maps measured on the MPM sand, as
//! fitted coefficients or a table (`terrain.rft.stress_maps`). Li et al. give alpha and zeta in
//! N/cm^3; here they are SI, N/m^3 (1 N/cm^3 = 1e6 N/m^3).
//!
//! **Signs** (checked against the physics, and the frame of Agarwal, Goldman and Kamrin, PNAS
//! 120:e2214017120, 2023): in the vertical plane of the element's velocity, let `r` be the
//! horizontal unit vector along the velocity ("forward") and `z` point up.
//! - `gamma` is the angle of the velocity below the horizontal: `v = |v| (cos g r - sin g z)`;
//!   `+pi/2` is straight down, `-pi/2` straight up.
//! - `beta` is the angle of the element's plane above the horizontal, positive when the plate
//!   rises towards the front: its lower face's normal is `(sin b) r - (cos b) z`, looking
//!   forward and down (a plate pushing sand down ahead of it: much lift and drag; at `gamma =
//!   0` `alpha_z(45 deg) = 0.363 zeta`, `alpha_z(-45 deg) = 0.049 zeta`).
//! - `alpha_z > 0` pushes up; `alpha_x > 0` pushes **backward**, against the horizontal
//!   motion (`alpha_x(pi/2, 0) = 0.377 zeta`: a vertical plate dragged sideways is held back).
//!   The force is `(alpha_z z - alpha_x r) |z| dA`.
//!
//! **Symmetries** ([`super::stress_law::StressLaw::alpha`] extends a law to all angles with
//! them): a plate is a line (pi-periodic in beta); the mirror image of a motion mirrors the
//! forces, so velocities with a backward component are mirrored into the measured range; and
//! vertical motion is its own mirror image, so alpha_x is odd in beta there.
//!
//! **3D: the vertical plane of the velocity.** Each element is reduced to Li's 2D problem in
//! the vertical plane containing its velocity (the local frame `r, z` of Agarwal et al.'s 3D
//! RFT, in which their model reduces to Li's 2D RFT when the element's normal lies in that
//! plane): gamma from the velocity, beta from the normal projected into the plane, and the area
//! weighted by the length of that projection (`sqrt(1 - (n.t)^2)` with `t = z x r`), so an
//! element sliding edge-on feels nothing and the force is continuous as the normal turns out of
//! the plane. The force has no component across the plane. For exactly vertical motion the
//! plane is the one containing the normal. Why this one: it is exact for motion in vertical
//! planes, which is how Li et al. applied RFT to their robot's legs and how this robot's legs
//! turn (about the hip axis y); gamma is always defined; and it needs no further fitted
//! functions. The general alternative, Treers, Cao and Stuart (IEEE RA-L 6:1394, 2021), works
//! in the plane of the normal and needs two empirical scaling functions and an out-of-plane
//! coefficient fitted to their medium, which one plate test cannot calibrate.
//!
//! **Elements** ([`body_elements`]): the colliders of a body as the CPIC coupling sees them
//! ([`super::body_surfaces`] with the element size as the thinness threshold). A solid box
//! gives its six faces, split into elements no longer than `element_size_m`, one-sided with
//! outward normals; only leading faces (`n . v > 0`) resist (Li et al.'s leading surface). A
//! chain of boxes thinner than one element (a leg) is a thin plate: the triangles of its
//! mid-surface sheet (`box_chain_sheet`), split likewise, two-sided: each element acts with
//! the normal that faces its motion, which is Li et al.'s plate element (their alpha covers a
//! plate, both faces, at every angle), at the depth of the mid-surface like the CPIC sheet.
//!
//! **Regularisation.** The RFT stress depends on the direction of motion, not on its speed, so
//! an element that nearly stops would flip its force every step. Each element's force is
//! scaled by `min(1, |v| / v_ref)` (`reference_speed_m_s`): below `v_ref` the terrain acts like
//! a stiff viscous damper, above it the stress is Li's. A body at rest on RFT ground therefore
//! creeps down at a speed below `v_ref` times its weight over the full RFT resistance.

use nalgebra::{DVector, Matrix3, Matrix6, Vector3, Vector6};
use rapier3d::glamx::Vec3;
use rapier3d::prelude::{
    ColliderSet, MultibodyIndex, MultibodyJointSet, Pose, RigidBody, RigidBodyHandle, RigidBodySet,
};

use super::config::{RftConfig, RftParams};
use crate::coupling::{body_surfaces, CpicSurface, SurfaceError};
use crate::robot::{RobotSim, LEGS};

/// A velocity whose horizontal part is below this fraction of its magnitude counts as
/// vertical (its vertical plane is then taken through the element's normal).
const VERTICAL_MOTION_FRACTION: f64 = 1e-9;
/// A triangle is split while its longest edge exceeds the element size by more than this
/// fraction (round-off of exactly fitting sizes).
const ELEMENT_SIZE_SLACK: f64 = 1e-6;

/// One surface element of a body, in the body's frame (the rapier body's position, not its
/// centre of mass).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceElement {
    /// Centre (m), body frame.
    pub centre_m: Vec3,
    /// Unit normal, body frame: outward for a solid's face; either side for a thin plate.
    pub normal: Vec3,
    /// Area (m^2).
    pub area_m2: f32,
    /// A thin plate's element: acts with whichever normal faces its motion. Otherwise only
    /// when leading (`n . v > 0`).
    pub two_sided: bool,
}

/// The terrain's force on one element (N, world axes) at depth `depth_m` (m, > 0 below the
/// surface) with unit normal `normal` and velocity `velocity_m_s` (m/s), both world axes, in
/// the vertical plane of its velocity (module docs), regularised: scaled by `min(1, |v| /
/// v_ref)`. Zero above the surface, at rest, and for a one-sided element that is not leading.
pub fn element_force_n(
    params: &RftParams,
    depth_m: f64,
    normal: Vector3<f64>,
    two_sided: bool,
    area_m2: f64,
    velocity_m_s: Vector3<f64>,
) -> Vector3<f64> {
    let speed = velocity_m_s.norm();
    let full = element_stress_n_m2(params, depth_m, normal, two_sided, velocity_m_s);
    full * area_m2 * (speed / params.reference_speed_m_s).min(1.0)
}

/// Li et al.'s stress on an element (N/m^2, world axes): [`element_force_n`] per unit area,
/// not regularised (the same at any nonzero speed).
fn element_stress_n_m2(
    params: &RftParams,
    depth_m: f64,
    normal: Vector3<f64>,
    two_sided: bool,
    velocity_m_s: Vector3<f64>,
) -> Vector3<f64> {
    let speed = velocity_m_s.norm();
    if depth_m <= 0.0 || speed == 0.0 || !speed.is_finite() {
        return Vector3::zeros();
    }
    let facing = normal.dot(&velocity_m_s);
    let normal = if facing > 0.0 {
        normal
    } else if two_sided {
        if facing < 0.0 {
            -normal
        } else {
            normal
        }
    } else {
        return Vector3::zeros();
    };
    let horizontal = Vector3::new(velocity_m_s.x, velocity_m_s.y, 0.0);
    let horizontal_speed = horizontal.norm();
    let vertical = horizontal_speed <= VERTICAL_MOTION_FRACTION * speed;
    let forward = if !vertical {
        horizontal / horizontal_speed
    } else {
        // Straight up or down: every vertical plane holds the velocity; take the normal's.
        let normal_horizontal = Vector3::new(normal.x, normal.y, 0.0);
        let length = normal_horizontal.norm();
        if length > 0.0 {
            normal_horizontal / length
        } else {
            Vector3::x()
        }
    };
    let (normal_forward, normal_up) = (normal.dot(&forward), normal.z);
    let in_plane_sq = normal_forward * normal_forward + normal_up * normal_up;
    if in_plane_sq == 0.0 {
        return Vector3::zeros();
    }
    // The plate's line in the (forward, up) plane makes angle beta with the horizontal; its
    // normal is +-(sin beta, -cos beta), and the law needs only the pi-periodic cos 2 beta and
    // sin 2 beta, which do not depend on that sign. Gamma: v = |v| (cos g r - sin g z).
    let cos_2b = (normal_up * normal_up - normal_forward * normal_forward) / in_plane_sq;
    let sin_2b = -2.0 * normal_forward * normal_up / in_plane_sq;
    let sin_g = -velocity_m_s.z / speed;
    let law = &params.law;
    let (alpha_x, alpha_z) = if vertical {
        law.alpha_vertical_cs(cos_2b, sin_2b, 1.0f64.copysign(sin_g))
    } else {
        law.alpha_in_range_cs(cos_2b, sin_2b, horizontal_speed / speed, sin_g)
    };
    let scale = law.unit_n_m3() * depth_m * in_plane_sq.sqrt();
    (Vector3::z() * alpha_z - forward * alpha_x) * scale
}

/// Surface elements of a rapier body's colliders (module docs): solid boxes give their faces,
/// chains of boxes thinner than `element_size_m` one two-sided sheet. Errors name the problem
/// (a collider that is not a box, thin boxes that do not form a chain).
pub fn body_elements(
    body: RigidBodyHandle,
    bodies: &RigidBodySet,
    colliders: &ColliderSet,
    element_size_m: f64,
) -> Result<Vec<SurfaceElement>, ElementsError> {
    let mut elements = Vec::new();
    for (pose, surface) in body_surfaces(body, bodies, colliders, element_size_m as f32)? {
        match surface {
            CpicSurface::Solid(shape) => {
                let cuboid = shape
                    .as_cuboid()
                    .ok_or_else(|| ElementsError::NotABox(format!("{:?}", shape.shape_type())))?;
                box_faces(&pose, cuboid.half_extents, element_size_m, &mut elements);
            }
            CpicSurface::Sheet(sheet) => {
                let mesh = sheet.mesh();
                let vertices = mesh.vertices();
                for tri in mesh.indices() {
                    let [a, b, c] = tri.map(|i| pose.transform_point(vertices[i as usize]));
                    split_triangle([a, b, c], element_size_m, &mut elements);
                }
            }
        }
    }
    Ok(elements)
}

/// The six faces of a box with half extents `half` at `pose`, each split into a grid of
/// elements no longer than `size` (m) along either side; outward normals, one-sided.
fn box_faces(pose: &Pose, half: Vec3, size: f64, out: &mut Vec<SurfaceElement>) {
    let h = half.to_array();
    for axis in 0..3 {
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        let cells = |a: usize| ((2.0 * h[a] as f64 / size).ceil() as usize).max(1);
        let (nu, nv) = (cells(u), cells(v));
        let (du, dv) = (2.0 * h[u] / nu as f32, 2.0 * h[v] / nv as f32);
        for sign in [-1.0f32, 1.0] {
            let normal = Vec3::AXES[axis] * sign;
            for i in 0..nu {
                for j in 0..nv {
                    let mut local = [0.0f32; 3];
                    local[axis] = sign * h[axis];
                    local[u] = -h[u] + (i as f32 + 0.5) * du;
                    local[v] = -h[v] + (j as f32 + 0.5) * dv;
                    out.push(SurfaceElement {
                        centre_m: pose.transform_point(Vec3::from(local)),
                        normal: pose.rotation * normal,
                        area_m2: du * dv,
                        two_sided: false,
                    });
                }
            }
        }
    }
}

/// A thin plate's triangle as two-sided elements: halved at the midpoint of its longest edge
/// until no edge is longer than `size` (m); each piece acts at its centroid (exact for a depth
/// linear over the piece). Halving the longest edge, not all three, gives a leg's narrow
/// triangles a quarter of the pieces at the same size.
fn split_triangle(corners: [Vec3; 3], size: f64, out: &mut Vec<SurfaceElement>) {
    let [a, b, c] = corners;
    let edges = [(b - a).length(), (c - b).length(), (a - c).length()];
    let longest = edges[0].max(edges[1]).max(edges[2]);
    if longest as f64 > size * (1.0 + ELEMENT_SIZE_SLACK) {
        // Rotate the corners so that the longest edge runs from the first to the second.
        let [p, q, r] = match edges.iter().position(|&e| e == longest) {
            Some(0) => [a, b, c],
            Some(1) => [b, c, a],
            _ => [c, a, b],
        };
        let middle = (p + q) * 0.5;
        split_triangle([p, middle, r], size, out);
        split_triangle([middle, q, r], size, out);
        return;
    }
    let doubled = (b - a).cross(c - a);
    out.push(SurfaceElement {
        centre_m: (a + b + c) / 3.0,
        normal: doubled.normalize(),
        area_m2: 0.5 * doubled.length(),
        two_sided: true,
    });
}

/// A body the terrain acts on.
#[derive(Clone, Debug)]
pub struct RftBody {
    /// For messages.
    pub name: String,
    pub body: RigidBodyHandle,
    pub elements: Vec<SurfaceElement>,
    /// The box around the element centres, body frame (m): lowest and highest corner. A body
    /// whose box, moved a step at the body's fastest point speed, stays above the surface
    /// feels nothing and is skipped.
    pub centre_bounds_m: [Vec3; 2],
}

impl RftBody {
    /// The lowest height (m) any element of the body (rigid body `rb`) can reach in a step of
    /// `dt_s`: the lowest corner of its box of element centres, lowered by a step at the
    /// fastest speed a point of the box can have.
    fn lowest_reach_m(&self, rb: &RigidBody, dt_s: f64) -> f64 {
        let [lo, hi] = self.centre_bounds_m;
        let (middle, half) = ((lo + hi) * 0.5, (hi - lo) * 0.5);
        let pose = rb.position();
        let middle_world = pose.transform_point(middle);
        let [x, y, z] = [Vec3::X, Vec3::Y, Vec3::Z].map(|axis| (pose.rotation * axis).z.abs());
        let lowest = middle_world.z as f64 - (x * half.x + y * half.y + z * half.z) as f64;
        let farthest = (middle_world - rb.center_of_mass()).length() + half.length();
        let fastest = rb.linvel().length() + rb.angvel().length() * farthest;
        lowest - dt_s * fastest as f64
    }

    /// Whether every element of the body stays above the surface at `surface_m` through a
    /// step of `dt_s` ([`Self::lowest_reach_m`]).
    fn above_surface_for(&self, rb: &RigidBody, surface_m: f64, dt_s: f64) -> bool {
        self.lowest_reach_m(rb, dt_s) > surface_m
    }
}

/// The terrain's total force on a body and its torque about the body's centre of mass, world
/// axes.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BodyWrench {
    /// Force (N).
    pub force_n: Vector3<f64>,
    /// Torque about the centre of mass (N m).
    pub torque_n_m: Vector3<f64>,
}

/// The implicit terms of a body's elements, summed as moments: isotropic point dampers of
/// coefficient `c` (N s/m) and vertical point springs of stiffness `k` (N/m) at arms `r` (m)
/// from its centre of mass. [`Self::matrix`] is the 6x6 matrix `C + K` they add up to (wrench =
/// `-C twist - K displacement`; force and torque about the centre of mass, the centre of mass's
/// velocity or displacement and the angular ones, world axes):
/// - a damper's point moves at `v + w x r`: `C += c [[1, -[r]x], [[r]x, -[r]x [r]x]]`, and
///   `-[r]x [r]x = |r|^2 1 - r r^T`;
/// - a spring's point rises by `g . (dx, dtheta)` with `g = (e_z, r x e_z)`: `K += k g g^T`.
#[derive(Clone, Copy, Debug, Default)]
struct ImplicitMoments {
    /// `sum c` (N s/m).
    damping: f64,
    /// `sum c r` (N s).
    damping_arm: Vector3<f64>,
    /// `sum c (|r|^2 1 - r r^T)` (N m s).
    damping_inertia: Matrix3<f64>,
    /// `sum k` (N/m).
    stiffness: f64,
    /// `sum k (r x e_z)` (N).
    stiffness_lever: Vector3<f64>,
    /// `sum k (r x e_z) (r x e_z)^T` (N m).
    stiffness_lever_sq: Matrix3<f64>,
}

impl ImplicitMoments {
    /// Adds a damper of coefficient `c` at arm `r`.
    fn add_damper(&mut self, c: f64, r: Vector3<f64>) {
        self.damping += c;
        self.damping_arm += r * c;
        self.damping_inertia += (Matrix3::identity() * r.norm_squared() - r * r.transpose()) * c;
    }

    /// Adds a vertical spring of stiffness `k` at arm `r`.
    fn add_depth_spring(&mut self, k: f64, r: Vector3<f64>) {
        let lever = r.cross(&Vector3::z());
        self.stiffness += k;
        self.stiffness_lever += lever * k;
        self.stiffness_lever_sq += lever * lever.transpose() * k;
    }

    /// `dt C + dt^2 K` for a step of `dt_s` (s).
    fn matrix(&self, dt_s: f64) -> Matrix6<f64> {
        let dt_sq = dt_s * dt_s;
        let arm_cross = self.damping_arm.cross_matrix() * dt_s;
        let lever = self.stiffness_lever * dt_sq;
        let mut m = Matrix6::zeros();
        m.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&(Matrix3::identity() * (dt_s * self.damping)));
        m.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-arm_cross));
        m.fixed_view_mut::<3, 3>(3, 0).copy_from(&arm_cross);
        m.fixed_view_mut::<3, 3>(3, 3)
            .copy_from(&(self.damping_inertia * dt_s + self.stiffness_lever_sq * dt_sq));
        m[(2, 2)] += dt_sq * self.stiffness;
        for j in 0..3 {
            m[(2, 3 + j)] += lever[j];
            m[(3 + j, 2)] += lever[j];
        }
        m
    }
}

/// Errors building an RFT terrain.
#[derive(thiserror::Error, Debug, Clone, PartialEq)]
pub enum RftError {
    #[error("{name}: its body is not in the rapier world")]
    MissingBody { name: String },
    #[error("{name}: cannot make its RFT surface elements: {source}")]
    Elements { name: String, source: ElementsError },
}

/// Why a body's colliders give no RFT surface elements.
#[derive(thiserror::Error, Debug, Clone, PartialEq)]
pub enum ElementsError {
    #[error(transparent)]
    Surface(#[from] SurfaceError),
    /// The shape type's name.
    #[error("RFT needs box collision shapes; found a {0}")]
    NotABox(String),
}

/// The implicit terms of one multibody's links in the terrain: (link id, 6x6 `dt C + dt^2 K`
/// about the link's centre of mass).
type LinkImplicitTerms = Vec<(usize, Matrix6<f64>)>;

/// A flat RFT terrain and the bodies it acts on.
///
/// [`Self::apply`] sets each body's RFT wrench at the start of a step as its user force, and
/// makes the step linearly implicit in the terrain's damping and depth stiffness.
///
/// Damping: the RFT force falls to zero with the speed below v_ref and flips with the
/// direction of motion: explicitly, a 2 g leg held in the sand by its motor chatters (its
/// speed jumps by `|F| dt r^2 / I` each step, about 1.5 rad/s at 0.5 ms), and the chatter walks
/// the robot. Each element acts like a damper of coefficient `c = |F_full| / max(|v|, v_ref)`
/// (the exact slope of the regularised force below v_ref, the secant above).
///
/// Stiffness: the force grows linearly with depth, a vertical spring `k = F_z / d` per element;
/// on the default (calibrated) zeta explicit depth forces walked the robot 11 % too far at
/// 1 ms steps and tipped it at 4 ms. Each element's force is taken at its depth predicted at
/// the end of the step, `d - dt v_z` (`F(x_n) + dt dF/dx v_n`), and `dt^2 k` joins the
/// implicit matrix.
///
/// Both are summed per link (`dt C_l + dt^2 K_l`, 6x6, about its centre of mass) and mapped into
/// the multibody's generalized coordinates with rapier's link Jacobians (`sum J_l^T (..) J_l`);
/// the diagonal `D` is added for the step as armature to rapier's mass matrix. Rapier then
/// solves `(M + D) (u_{n+1} - u_n) = dt (W + other forces)`: linearly implicit Euler with the
/// diagonal of the terrain's Jacobian (the off-diagonal couplings stay explicit). Measured
/// (tests/rft.rs): a standing robot settles without chatter, and the walk with the `auto` step
/// (1 ms on the default zeta, 8 ms on poppy seeds) is within 3 % of 0.25 ms steps. Bodies that
/// are not multibody links get the explicit wrench only. (A full-matrix bound such as
/// Gershgorin's row sums over-damps the body's coupled degrees of freedom and made the robot
/// tumble on stiff ground; velocity motors on joints to a fixed body left an unconverged solver
/// velocity that the robot rode on.)
#[derive(Clone, Debug)]
pub struct RftTerrain {
    params: RftParams,
    bodies: Vec<RftBody>,
    /// Each multibody the terrain acts on, with its armature before the terrain's (kg or
    /// kg m^2 per degree of freedom), recorded by the first [`Self::apply`].
    armatures: Vec<(MultibodyIndex, DVector<f32>)>,
}

fn to_f64(v: Vec3) -> Vector3<f64> {
    Vector3::new(v.x as f64, v.y as f64, v.z as f64)
}

fn to_vec3(v: Vector3<f64>) -> Vec3 {
    Vec3::new(v.x as f32, v.y as f32, v.z as f32)
}

impl RftTerrain {
    /// The terrain acting on `parts` (name, body), each body's colliders turned into surface
    /// elements ([`body_elements`]).
    pub fn new(
        params: RftParams,
        parts: impl IntoIterator<Item = (String, RigidBodyHandle)>,
        bodies: &RigidBodySet,
        colliders: &ColliderSet,
    ) -> Result<Self, RftError> {
        let mut out = Vec::new();
        for (name, body) in parts {
            if bodies.get(body).is_none() {
                return Err(RftError::MissingBody { name });
            }
            let elements = body_elements(body, bodies, colliders, params.element_size_m).map_err(
                |source| RftError::Elements {
                    name: name.clone(),
                    source,
                },
            )?;
            let centre_bounds_m = elements.iter().fold(
                [Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)],
                |[lo, hi], e| [lo.min(e.centre_m), hi.max(e.centre_m)],
            );
            out.push(RftBody {
                name,
                body,
                elements,
                centre_bounds_m,
            });
        }
        Ok(RftTerrain {
            params,
            bodies: out,
            armatures: Vec::new(),
        })
    }

    pub fn params(&self) -> &RftParams {
        &self.params
    }

    /// Whether every collider on a moving body belongs to one of the terrain's bodies (fixed
    /// ones, such as the floor, aside): then [`Self::lowest_reach_m`] bounds every moving
    /// collider.
    pub fn covers_moving_colliders(&self, bodies: &RigidBodySet, colliders: &ColliderSet) -> bool {
        colliders
            .iter()
            .all(|(_, collider)| match collider.parent() {
                Some(parent) => {
                    bodies.get(parent).is_none_or(|b| b.is_fixed())
                        || self.bodies.iter().any(|b| b.body == parent)
                }
                None => true,
            })
    }

    /// The lowest height (m) an element of any body can reach in a step of `dt_s`
    /// (conservative: from each body's box of element centres and its fastest point).
    pub fn lowest_reach_m(&self, bodies: &RigidBodySet, dt_s: f64) -> f64 {
        self.bodies
            .iter()
            .map(|b| b.lowest_reach_m(&bodies[b.body], dt_s))
            .fold(f64::INFINITY, f64::min)
    }

    /// The bodies, in the order of the wrenches.
    pub fn bodies(&self) -> &[RftBody] {
        &self.bodies
    }

    /// The terrain's regularised wrench on each body at the bodies' present poses and
    /// velocities (element velocity = linvel + angvel x r about the centre of mass), in
    /// [`Self::bodies`] order.
    pub fn wrenches(&self, bodies: &RigidBodySet) -> Vec<BodyWrench> {
        self.bodies
            .iter()
            .map(|b| self.body_wrench(&bodies[b.body], b, 0.0).0)
            .collect()
    }

    /// The wrench on `body` (rigid body `rb`) and the 6x6 matrix `dt C + dt^2 K` of its damper
    /// C and depth stiffness K (type docs, [`add_point_damper`], [`add_point_depth_spring`]),
    /// with every element's depth predicted `dt_s` ahead (`dt_s` = 0: the present wrench).
    fn body_wrench(&self, rb: &RigidBody, body: &RftBody, dt_s: f64) -> (BodyWrench, Matrix6<f64>) {
        let mut wrench = BodyWrench::default();
        let mut moments = ImplicitMoments::default();
        if body.above_surface_for(rb, self.params.surface_height_m, dt_s) {
            return (wrench, moments.matrix(dt_s));
        }
        let pose = rb.position();
        let com = to_f64(rb.center_of_mass());
        let (linvel, angvel) = (to_f64(rb.linvel()), to_f64(rb.angvel()));
        let v_ref = self.params.reference_speed_m_s;
        for e in &body.elements {
            let centre = to_f64(pose.transform_point(e.centre_m));
            let arm = centre - com;
            let velocity = linvel + angvel.cross(&arm);
            // Depth at the end of the step if the element keeps its velocity: the force is
            // `F(d_n) + dt dF/dx v_n`, the explicit half of the linearly implicit spring.
            let depth_m = self.params.surface_height_m - centre.z - dt_s * velocity.z;
            if depth_m <= 0.0 {
                continue;
            }
            let full = element_stress_n_m2(
                &self.params,
                depth_m,
                to_f64(pose.rotation * e.normal),
                e.two_sided,
                velocity,
            ) * e.area_m2 as f64;
            let speed = velocity.norm();
            let force = full * (speed / v_ref).min(1.0);
            let magnitude = full.norm();
            if magnitude > 0.0 {
                moments.add_damper(magnitude / speed.max(v_ref), arm);
                // The force grows linearly with depth: vertical stiffness F_z / d (N/m).
                moments.add_depth_spring(force.z.max(0.0) / depth_m, arm);
            }
            wrench.force_n += force;
            wrench.torque_n_m += arm.cross(&force);
        }
        (wrench, moments.matrix(dt_s))
    }

    /// Sets each body's RFT wrench (depths predicted `dt_s` ahead) as its user force and torque
    /// (the previous ones are replaced; multibody links take loads this way), and the
    /// terrain's implicit terms as armature on the multibodies' degrees of freedom, for the
    /// next rapier step, which must be `dt_s` seconds long (type docs). Returns the wrenches.
    pub fn apply(
        &mut self,
        bodies: &mut RigidBodySet,
        multibodies: &mut MultibodyJointSet,
        dt_s: f64,
    ) -> Vec<BodyWrench> {
        let mut wrenches = Vec::with_capacity(self.bodies.len());
        // Per multibody: (link id, dt C + dt^2 K) of its links in the terrain.
        let mut implicit_terms: Vec<(MultibodyIndex, LinkImplicitTerms)> = Vec::new();
        for b in &self.bodies {
            let (wrench, implicit) = self.body_wrench(&bodies[b.body], b, dt_s);
            let rb = &mut bodies[b.body];
            rb.reset_forces(false);
            rb.reset_torques(false);
            rb.add_force(to_vec3(wrench.force_n), true);
            rb.add_torque(to_vec3(wrench.torque_n_m), true);
            wrenches.push(wrench);
            if let Some(link) = multibodies.rigid_body_link(b.body) {
                match implicit_terms
                    .iter_mut()
                    .find(|(m, _)| *m == link.multibody)
                {
                    Some((_, links)) => links.push((link.id, implicit)),
                    None => implicit_terms.push((link.multibody, vec![(link.id, implicit)])),
                }
            }
        }
        for (index, links) in implicit_terms {
            let Some(mb) = multibodies.get_multibody_mut(index) else {
                continue;
            };
            // The armature without the terrain, kept from the first step.
            let slot = match self.armatures.iter().position(|(m, _)| *m == index) {
                Some(slot) => slot,
                None => {
                    self.armatures.push((index, mb.armature().clone()));
                    self.armatures.len() - 1
                }
            };
            let baseline = &self.armatures[slot].1;
            // Only the diagonal of `sum J^T (dt C + dt^2 K) J` is used: its k-th entry is
            // `sum j_k^T (dt C + dt^2 K) j_k` over the links' Jacobian columns `j_k`.
            let ndofs = mb.ndofs();
            let mut diagonal = vec![0.0f64; ndofs];
            for (link, implicit) in &links {
                let jacobian = mb.body_jacobian(*link);
                for (k, d) in diagonal.iter_mut().enumerate() {
                    let column: Vector6<f64> =
                        jacobian.fixed_view::<6, 1>(0, k).into_owned().cast();
                    *d += column.dot(&(implicit * column));
                }
            }
            let armature = mb.armature_mut();
            for k in 0..ndofs.min(armature.len()) {
                armature[k] = baseline[k] + diagonal[k].max(0.0) as f32;
            }
        }
        wrenches
    }
}

/// The RFT terrain acting on the robot's body and legs (every collision box; the legs' thin
/// boxes as plates), in the order body, then [`LEGS`].
pub fn robot_terrain(robot: &RobotSim, cfg: &RftConfig) -> Result<RftTerrain, RftError> {
    let parts = std::iter::once(("body".to_string(), robot.body_handle())).chain(
        LEGS.iter()
            .zip(robot.leg_handles())
            .map(|(leg, h)| (leg.link_name(), h)),
    );
    let world = robot.world();
    RftTerrain::new(cfg.params(), parts, &world.bodies, &world.colliders)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::terrain::stress_law::StressLaw;
    use rapier3d::prelude::{ColliderBuilder, RigidBodyBuilder};
    use std::f64::consts::FRAC_PI_2;

    const ZETA: f64 = 4.0e5;

    fn params() -> RftParams {
        RftParams {
            law: StressLaw::generic(ZETA),
            surface_height_m: 0.0,
            element_size_m: 0.004,
            reference_speed_m_s: 0.01,
        }
    }

    /// A kinematic body holding one box collider (half extents, m), at `centre` moving at
    /// `velocity`, and the terrain acting on it.
    fn plate(half: [f32; 3], centre: [f32; 3], velocity: [f32; 3]) -> (RigidBodySet, RftTerrain) {
        let mut bodies = RigidBodySet::new();
        let mut colliders = ColliderSet::new();
        let body = bodies.insert(
            RigidBodyBuilder::kinematic_velocity_based()
                .translation(Vec3::from(centre))
                .linvel(Vec3::from(velocity)),
        );
        colliders.insert_with_parent(
            ColliderBuilder::cuboid(half[0], half[1], half[2]),
            body,
            &mut bodies,
        );
        let terrain =
            RftTerrain::new(params(), [("plate".to_string(), body)], &bodies, &colliders).unwrap();
        (bodies, terrain)
    }

    /// Li et al.'s generic shape per unit zeta.
    fn alpha(beta: f64, gamma: f64) -> (f64, f64) {
        StressLaw::generic(1.0).alpha(beta, gamma)
    }

    #[test]
    fn zeta_is_the_vertical_stress_of_a_horizontal_plate_pressed_down() {
        let (x, z) = alpha(0.0, FRAC_PI_2);
        assert!((z - 1.0).abs() < 1e-12, "alpha_z(0, 90 deg) = {z}");
        assert_eq!(
            x, 0.0,
            "no sideways force on a horizontal plate moving straight down"
        );
    }

    #[test]
    fn signs_follow_the_physics() {
        // A horizontal plate pulled straight up is held down, more weakly than pushed down.
        let (_, up) = alpha(0.0, -FRAC_PI_2);
        assert!(up < 0.0 && up.abs() < 1.0, "alpha_z(0, -90 deg) = {up}");
        // Dragged horizontally: drag (alpha_x > 0 opposes the motion) and lift.
        let (drag, lift) = alpha(0.0, 0.0);
        assert!(drag > 0.0 && lift > 0.0);
        // A plate rising towards the front pushes sand down ahead of it: more lift and drag
        // than the one falling towards the front.
        let (drag_up, lift_up) = alpha(FRAC_PI_2 / 2.0, 0.0);
        let (drag_down, lift_down) = alpha(-FRAC_PI_2 / 2.0, 0.0);
        assert!(lift_up > lift_down && drag_up > drag_down);
    }

    #[test]
    fn horizontal_plate_pressed_straight_down_feels_zeta_depth_area() {
        // 2 cm x 3 cm, 1 mm thick (a thin plate: its mid-plane, two-sided), 15 mm deep.
        let (half, depth) = ([0.01, 0.015, 0.0005], 0.015);
        let (bodies, terrain) = plate(half, [0.1, 0.0, -depth], [0.0, 0.0, -0.1]);
        assert!(terrain.bodies()[0].elements.iter().all(|e| e.two_sided));
        let w = terrain.wrenches(&bodies)[0];
        let area = 4.0 * (half[0] * half[1]) as f64;
        let expected = ZETA * depth as f64 * area;
        assert!(
            (w.force_n.z - expected).abs() < 1e-6 * expected,
            "{} N vs {expected} N",
            w.force_n.z
        );
        assert!(w.force_n.x.abs() < 1e-9 * expected && w.force_n.y.abs() < 1e-9 * expected);
        assert!(w.torque_n_m.norm() < 1e-5 * expected * 0.01);
        // A solid box (2 cm thick): its bottom face leads, at its own depth; the sides do not.
        let (half, depth) = ([0.01, 0.015, 0.01], 0.03);
        let (bodies, terrain) = plate(half, [0.0, 0.0, -depth], [0.0, 0.0, -0.1]);
        let w = terrain.wrenches(&bodies)[0];
        let expected = ZETA * (depth + half[2]) as f64 * 4.0 * (half[0] * half[1]) as f64;
        assert!((w.force_n.z - expected).abs() < 1e-6 * expected);
    }

    #[test]
    fn element_above_the_surface_feels_nothing() {
        let (bodies, terrain) = plate([0.01, 0.01, 0.0005], [0.0, 0.0, 0.001], [0.0, 0.0, -0.1]);
        assert_eq!(terrain.wrenches(&bodies)[0], BodyWrench::default());
        let up = element_force_n(
            &params(),
            -0.01,
            Vector3::z(),
            true,
            1e-4,
            Vector3::new(0.0, 0.0, -1.0),
        );
        assert_eq!(up, Vector3::zeros());
    }

    #[test]
    fn plate_moving_horizontally_is_held_back() {
        for velocity in [[0.2, 0.0, 0.0], [-0.1, 0.1, 0.0]] {
            // A vertical plate, face on to x, and a horizontal one, both 1 cm deep.
            for half in [[0.0005, 0.01, 0.01], [0.01, 0.01, 0.0005]] {
                let (bodies, terrain) = plate(half, [0.0, 0.0, -0.02], velocity);
                let w = terrain.wrenches(&bodies)[0];
                let v = Vector3::new(velocity[0], velocity[1], 0.0).cast::<f64>();
                assert!(
                    w.force_n.dot(&v) < 0.0,
                    "plate {half:?} moving {velocity:?}: force {:?}",
                    w.force_n
                );
            }
        }
    }

    #[test]
    fn element_force_is_the_angle_form_in_the_plane_of_the_velocity() {
        let p = params();
        let mut checked = 0;
        for i in 0..200 {
            let t = i as f64;
            let normal =
                Vector3::new((1.3 * t).sin(), (0.7 * t + 1.0).cos(), (2.1 * t).sin()).normalize();
            let velocity = Vector3::new((0.9 * t).cos(), (1.7 * t).sin(), (0.4 * t + 2.0).sin());
            let force = element_force_n(&p, 0.01, normal, false, 1e-4, velocity);
            if normal.dot(&velocity) <= 0.0 {
                assert_eq!(force, Vector3::zeros(), "trailing faces feel nothing");
                continue;
            }
            let horizontal = Vector3::new(velocity.x, velocity.y, 0.0);
            let forward = horizontal.normalize();
            let gamma = (-velocity.z).atan2(horizontal.norm());
            let (nf, nz) = (normal.dot(&forward), normal.z);
            let beta = nf.atan2(-nz);
            let (ax, az) = alpha(beta, gamma);
            let scale = ZETA * 0.01 * 1e-4 * nf.hypot(nz);
            let expected = (Vector3::z() * az - forward * ax) * scale;
            assert!((force - expected).norm() < 1e-9 * expected.norm().max(1e-12));
            checked += 1;
        }
        assert!(checked > 50);
    }

    #[test]
    fn slow_elements_feel_a_proportional_force() {
        let p = params();
        let force = |speed: f64| {
            element_force_n(&p, 0.01, -Vector3::z(), false, 1e-4, Vector3::z() * -speed).z
        };
        let full = force(1.0);
        assert!((force(p.reference_speed_m_s) - full).abs() < 1e-12 * full);
        assert!((force(0.25 * p.reference_speed_m_s) - 0.25 * full).abs() < 1e-12 * full);
        assert_eq!(force(0.0), 0.0);
    }

    #[test]
    fn implicit_moments_sum_the_point_dampers_and_springs() {
        // Each point's own 6x6 terms, built directly (type docs of ImplicitMoments).
        let point_terms = |c: f64, k: f64, r: Vector3<f64>| {
            let cross = r.cross_matrix();
            let mut damper = Matrix6::zeros();
            damper
                .fixed_view_mut::<3, 3>(0, 0)
                .copy_from(&Matrix3::identity());
            damper.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-cross));
            damper.fixed_view_mut::<3, 3>(3, 0).copy_from(&cross);
            damper
                .fixed_view_mut::<3, 3>(3, 3)
                .copy_from(&(-(cross * cross)));
            let mut g = Vector6::zeros();
            g[2] = 1.0;
            g.fixed_rows_mut::<3>(3).copy_from(&r.cross(&Vector3::z()));
            (damper * c, g * g.transpose() * k)
        };
        let dt = 0.003;
        let (mut moments, mut expected) = (ImplicitMoments::default(), Matrix6::zeros());
        for i in 0..7 {
            let t = i as f64;
            let r = Vector3::new((1.3 * t).sin(), (0.7 * t).cos(), (2.1 * t + 0.5).sin()) * 0.03;
            let (c, k) = (0.5 + t, 100.0 * (1.0 + t * t));
            moments.add_damper(c, r);
            moments.add_depth_spring(k, r);
            let (damper, spring) = point_terms(c, k, r);
            expected += damper * dt + spring * (dt * dt);
        }
        let got = moments.matrix(dt);
        assert!(
            (got - expected).norm() < 1e-12 * expected.norm(),
            "{got} vs {expected}"
        );
    }

    #[test]
    fn a_body_is_skipped_only_when_no_element_can_reach_the_surface() {
        // A 2 x 3 x 1 cm box turned and moving; the cull must never skip an element that the
        // step brings below the surface.
        let mut skipped = 0;
        for i in 0..400 {
            let t = i as f64;
            let centre = [0.0, 0.0, (0.02 * (0.37 * t).sin()) as f32];
            let velocity = [0.0, 0.0, (-0.5 * (0.23 * t).cos()) as f32];
            let (mut bodies, terrain) = plate([0.01, 0.015, 0.005], centre, velocity);
            let handle = terrain.bodies()[0].body;
            let rb = &mut bodies[handle];
            let axis = Vec3::new((0.3 * t).sin() as f32, 1.0, (0.7 * t).cos() as f32).normalize();
            rb.set_rotation(rapier3d::glamx::Quat::from_axis_angle(axis, t as f32), true);
            rb.set_angvel(axis * (3.0 * (0.11 * t).sin()) as f32, true);
            let body = &terrain.bodies()[0];
            let dt = 0.004;
            if !body.above_surface_for(&bodies[handle], 0.0, dt) {
                continue;
            }
            skipped += 1;
            let rb = &bodies[handle];
            let com = rb.center_of_mass();
            for e in &body.elements {
                let p = rb.position().transform_point(e.centre_m);
                let v = rb.linvel() + rb.angvel().cross(p - com);
                assert!(
                    p.z + dt as f32 * v.z > 0.0,
                    "skipped an element reaching the sand"
                );
            }
        }
        assert!(
            skipped > 50,
            "the cull skips bodies above the sand ({skipped})"
        );
    }

    #[test]
    fn solid_faces_and_thin_sheets_cover_the_area() {
        let size = params().element_size_m;
        let mut out = Vec::new();
        box_faces(
            &Pose::IDENTITY,
            Vec3::new(0.01, 0.005, 0.003),
            size,
            &mut out,
        );
        let area: f64 = out.iter().map(|e| e.area_m2 as f64).sum();
        let expected = 8.0 * (0.01 * 0.005 + 0.005 * 0.003 + 0.003 * 0.01);
        assert!((area - expected).abs() < 1e-6 * expected);
        let mut tri = Vec::new();
        let corners = [
            Vec3::ZERO,
            Vec3::new(0.02, 0.0, 0.0),
            Vec3::new(0.0, 0.01, 0.0),
        ];
        split_triangle(corners, size, &mut tri);
        let area: f64 = tri.iter().map(|e| e.area_m2 as f64).sum();
        assert!((area - 1e-4).abs() < 1e-6 * 1e-4);
        // No piece is larger than an equilateral triangle of side `size`, and halving the
        // longest edge needs fewer pieces than splitting every edge (64 here).
        let largest = 3f64.sqrt() / 4.0 * size * size;
        assert!(tri
            .iter()
            .all(|e| (e.area_m2 as f64) <= largest * (1.0 + 1e-6)));
        assert!(tri.len() < 64, "{} pieces", tri.len());
    }
}
