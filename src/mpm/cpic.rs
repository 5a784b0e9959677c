//! CPIC, compatible particle-in-cell (Hu et al. 2018, "A moving least squares material point
//! method with displacement discontinuity and two-way rigid body coupling", section 5): rigid
//! colliders thinner than a grid cell neither leak sand nor go unfelt.
//!
//! The solver knows colliders only as plain data: a colour per grid node near them (computed by
//! `crate::coupling` from their shapes) and their rigid motion. Per substep (`docs/physics.md`,
//! section 4):
//! - node colours: bit `2r` is the node's affinity with collider `r` (it lies in the collider's
//!   narrow band and projects onto the surface proper), bit `2r + 1` its side of the surface;
//! - particle tags, kept between substeps: the same two bits per collider. A collider newly in a
//!   particle's stencil gets the side its stencil nodes vote for; one already in range keeps its
//!   side, which is what stops sand tunnelling through a thin shell;
//! - a node and a particle are compatible unless both have affinity with some collider and lie
//!   on different sides of it. P2G skips incompatible nodes and hands the momentum the particle
//!   would have exchanged there to the collider; G2P reads a ghost velocity there instead (the
//!   particle's own velocity, friction-projected against the collider's surface velocity);
//! - a particle found slightly on the wrong side is put back on the surface and loses its inward
//!   velocity relative to the collider, whose reaction goes to the collider; against a collider
//!   that yields, relative to the motion the collider shares with all such particles of the
//!   substep (`settle_penalty` in `solver/g2p.rs`).

use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};

use super::boundary::friction_project;
use super::grid::{node_in_arena, BLOCK_NODES};
use super::kernel::{Stencil, STENCIL};

/// Colliders one grid can tell apart: two bits each in a `u64`.
pub const MAX_COLLIDERS: usize = 32;
/// The affinity bits (even positions) of a colour or tag.
const AFFINITY_BITS: u64 = 0x5555_5555_5555_5555;
/// Penetration (in grid cells) from which a particle on the wrong side is pushed back; below it
/// the ghost velocities suffice.
pub const PENALTY_MIN_CELLS: f32 = 0.05;
/// Penetration (in grid cells) beyond which a particle is taken to belong to the other side
/// (it is not pushed across a whole collider).
pub const PENALTY_MAX_CELLS: f32 = 0.3;

/// Rigid motion and contact law of one collider during a substep.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ColliderMotion {
    /// Velocity of the centre (m/s).
    pub linear_m_s: Vector3<f32>,
    /// Angular velocity (rad/s).
    pub angular_rad_s: Vector3<f32>,
    /// Centre of mass, the reference point of the motion and of angular impulses (m).
    pub centre_m: Vector3<f32>,
    /// Coulomb friction coefficient between sand and the collider (dimensionless).
    pub friction: f32,
    /// The inertia that yields to the sand within a substep, about `centre_m`; `None` for
    /// colliders that do not yield (one-way, kinematic).
    pub yield_inertia: Option<YieldInertia>,
    /// Change of the centre's velocity (m/s) over the substep from every load but the sand's
    /// (gravity, joints, motors, contacts), as predicted by the coupling; zero for none. The
    /// yield meets the sand with the velocity the body will have (`yielded`).
    pub load_kick_m_s: Vector3<f32>,
    /// The same for the angular velocity (rad/s).
    pub load_kick_rad_s: Vector3<f32>,
}

/// Inertia that moves with a collider within a substep, about the collider's centre, as a
/// spatial inertia (6x6): the momentum and angular momentum about the centre of a rigid motion
/// `(v, w)` given there. Its body's own (free bodies); that of all the bodies its joints and
/// motors hold it to (a robot's leg locked to the whole robot:
/// `crate::coupling::Coupling::with_rigid_group`); or the inertia a multibody presents at the
/// link, its joints free (`crate::coupling::Coupling::with_articulation`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct YieldInertia {
    spatial: Matrix6<f64>,
}

impl YieldInertia {
    /// A free body about its own centre of mass, isotropic with its smallest principal moment
    /// `inertia_kg_m2` (which errs on the yielding side).
    pub fn free_body(mass_kg: f64, inertia_kg_m2: f64) -> Self {
        Self::rigid(
            mass_kg,
            &Vector3::zeros(),
            &(Matrix3::identity() * inertia_kg_m2),
        )
    }

    /// One rigid body of mass `mass_kg`, first moment `m (c - centre)` (kg m; zero when the
    /// centre is its centre of mass) and inertia tensor `inertia_kg_m2` about the centre.
    pub fn rigid(
        mass_kg: f64,
        first_moment_kg_m: &Vector3<f64>,
        inertia_kg_m2: &Matrix3<f64>,
    ) -> Self {
        YieldInertia {
            spatial: spatial_inertia(mass_kg, first_moment_kg_m, inertia_kg_m2),
        }
    }

    /// A spatial inertia given whole (a multibody's operational-space inertia at a link).
    pub fn from_spatial(spatial: Matrix6<f64>) -> Self {
        YieldInertia { spatial }
    }

    /// Parts held together as one rigid body, each `(mass (kg), centre of mass (m), inertia
    /// tensor about its centre of mass in world axes (kg m^2))`, about `centre` (m): the masses
    /// and first moments add, the inertias by the parallel-axis theorem.
    pub fn of_parts(
        parts: impl IntoIterator<Item = (f64, Vector3<f64>, Matrix3<f64>)>,
        centre: &Vector3<f64>,
    ) -> Self {
        let (mut mass_kg, mut first_moment, mut inertia) =
            (0.0, Vector3::zeros(), Matrix3::zeros());
        for (mass, com, own) in parts {
            let offset = com - centre;
            mass_kg += mass;
            first_moment += offset * mass;
            inertia += own
                + (Matrix3::identity() * offset.norm_squared() - offset * offset.transpose())
                    * mass;
        }
        Self::rigid(mass_kg, &first_moment, &inertia)
    }

    /// The spatial inertia (6x6) about the centre.
    pub fn spatial(&self) -> &Matrix6<f64> {
        &self.spatial
    }

    /// Change of a rigid motion `(m/s, rad/s)` at the centre that an impulse `(N s, N m s
    /// about the centre)` gives this inertia; None if it is singular.
    pub fn velocity_change(
        &self,
        linear_n_s: &Vector3<f64>,
        angular_n_m_s: &Vector3<f64>,
    ) -> Option<(Vector3<f64>, Vector3<f64>)> {
        if !self.is_valid() {
            return None;
        }
        let impulse = Vector6::new(
            linear_n_s.x,
            linear_n_s.y,
            linear_n_s.z,
            angular_n_m_s.x,
            angular_n_m_s.y,
            angular_n_m_s.z,
        );
        let change = self.spatial().cholesky()?.solve(&impulse);
        Some((
            change.fixed_rows::<3>(0).into_owned(),
            change.fixed_rows::<3>(3).into_owned(),
        ))
    }

    /// Usable: finite, with a positive mass and a positive inertia trace (a singular system is
    /// caught by the Cholesky factorisation, which then leaves the motion as it is).
    fn is_valid(&self) -> bool {
        let s = &self.spatial;
        s.iter().all(|v| v.is_finite())
            && s.fixed_view::<3, 3>(0, 0).trace() > 0.0
            && s.fixed_view::<3, 3>(3, 3).trace() > 0.0
    }
}

/// `[[m 1, -[S]x], [[S]x, I]]` for mass `m` (kg), first moment `S` (kg m) and inertia tensor
/// `I` (kg m^2) about one point: the momentum (N s) and angular momentum about that point
/// (N m s) of a rigid motion (m/s, rad/s) given there.
fn spatial_inertia(mass: f64, first_moment: &Vector3<f64>, inertia: &Matrix3<f64>) -> Matrix6<f64> {
    let s_cross = first_moment.cross_matrix();
    let mut m = Matrix6::<f64>::zeros();
    m.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&(Matrix3::identity() * mass));
    m.fixed_view_mut::<3, 3>(0, 3).copy_from(&-s_cross);
    m.fixed_view_mut::<3, 3>(3, 0).copy_from(&s_cross);
    m.fixed_view_mut::<3, 3>(3, 3).copy_from(inertia);
    m
}

impl ColliderMotion {
    /// The motion G2P uses after P2G. The collider, with the inertia that yields with it
    /// (spatial inertia `M_b` about its centre), meets at incompatible nodes (`p2g`) sand of
    /// mass `M_s`, first moment `S = sum w m r`, inertia tensor `I_s = sum w m (|r|^2 1 - r
    /// r^T)`, momentum `P_s` and angular momentum `L_s` (all about the centre). Body and sand
    /// are given the one rigid motion `(v*, w*)` that keeps their momentum and angular momentum
    /// (a perfectly inelastic exchange; `(v, w)` the collider's motion plus the predicted load
    /// kick, zero unless the coupling predicts it):
    ///
    /// ```text
    /// (M_b + M_sand) (v*, w*) = M_b (v, w) + (P_s, L_s),   M_sand = [[M_s 1, -[S]x], [[S]x, I_s]]
    /// ```
    ///
    /// (`M_b (v, w)` is what the inertia would carry moving with the collider; only the change
    /// `(v* - v, w* - w)` matters, so the yielding inertia need not move with the collider, as a
    /// robot does not move with its leg.) The ghost velocities then move the sand with that
    /// motion. When the yielding inertia is the body's own, the impulse the body receives
    /// changes its motion by about the difference: never more than the relative motion, so a
    /// light body (a 2 g plate) meeting much more sand stays stable in this explicit exchange
    /// (a group's impulse lands on one light link, which holds no such bound). Heavy bodies
    /// keep their own motion. The exchange bounds the force the sand can exert over a substep
    /// `dt` by about `M_b v_rel / dt`: carrying a load `F` takes a relative motion `F dt / M_b`,
    /// a creep that grows with the step (`docs/physics.md`, CPIC step 7).
    ///
    /// With no sand met the motion stays the collider's own, without the kick: nothing is
    /// exchanged.
    pub fn yielded(&self, p2g: Option<&ColliderImpulse>) -> ColliderMotion {
        let Some(body) = self.yield_inertia.filter(YieldInertia::is_valid) else {
            return *self;
        };
        let Some(p2g) = p2g.filter(|p| p.sand_mass_kg > 0.0) else {
            return *self;
        };
        let (v, w) = (
            (self.linear_m_s + self.load_kick_m_s).cast::<f64>(),
            (self.angular_rad_s + self.load_kick_rad_s).cast::<f64>(),
        );
        let body = *body.spatial();
        let system =
            body + spatial_inertia(p2g.sand_mass_kg, &p2g.sand_first_moment, &p2g.sand_inertia);
        let carried = body * Vector6::new(v.x, v.y, v.z, w.x, w.y, w.z);
        let (lin, ang) = (p2g.linear_n_s, p2g.angular_n_m_s);
        let rhs = carried + Vector6::new(lin.x, lin.y, lin.z, ang.x, ang.y, ang.z);
        // The system is a sum of rigid-body spatial inertias: symmetric positive definite.
        let Some(motion) = system.cholesky().map(|c| c.solve(&rhs)) else {
            return *self;
        };
        ColliderMotion {
            linear_m_s: motion.fixed_rows::<3>(0).into_owned().cast::<f32>(),
            angular_rad_s: motion.fixed_rows::<3>(3).into_owned().cast::<f32>(),
            ..*self
        }
    }

    /// Velocity of the collider's material point at `x` (m/s).
    #[inline]
    pub fn velocity_at(&self, x: &Vector3<f32>) -> Vector3<f32> {
        self.linear_m_s + self.angular_rad_s.cross(&(x - self.centre_m))
    }
}

/// What CPIC knows of one grid node.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct NodeColour {
    /// Affinity (bit `2r`) and side (bit `2r + 1`, set on the positive side) per collider.
    pub bits: u64,
    /// The closest collider with affinity.
    pub closest: u8,
    /// Distance to the closest collider, positive on its positive side (m).
    pub signed_distance_m: f32,
    /// Unit surface normal of the closest collider at the closest point, pointing to its
    /// positive side.
    pub normal: [f32; 3],
    /// Plain grid-boundary method (kept to show where it fails): 1 + the index of a collider
    /// whose velocity this node takes in the grid update, or 0.
    pub imposed: u8,
}

impl NodeColour {
    /// Marks affinity with collider `r` on the given side.
    pub fn set(&mut self, r: usize, positive_side: bool) {
        self.bits |= affinity_bit(r) | if positive_side { side_bit(r) } else { 0 };
    }
}

/// Colours of the nodes of one grid block, in block order.
pub type ColourBlock = [NodeColour; BLOCK_NODES];

/// Momentum handed to a collider in one substep.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ColliderImpulse {
    /// Linear impulse (N s).
    pub linear_n_s: Vector3<f64>,
    /// Angular impulse about the collider's centre (N m s).
    pub angular_n_m_s: Vector3<f64>,
    /// Mass of sand (kg) that met the collider at incompatible nodes in P2G (weights times
    /// particle masses): what the collider exchanged momentum with.
    pub sand_mass_kg: f64,
    /// First moment `sum w m r` of that sand about the collider's centre (kg m).
    pub sand_first_moment: Vector3<f64>,
    /// Inertia tensor `sum w m (|r|^2 1 - r r^T)` of that sand about the collider's centre
    /// (kg m^2).
    pub sand_inertia: Matrix3<f64>,
}

impl ColliderImpulse {
    /// Adds the impulse `j` (N s) applied at `x` (m) to a collider centred at `centre` (m).
    #[inline]
    pub fn add_at(&mut self, j: Vector3<f32>, x: &Vector3<f32>, centre: &Vector3<f32>) {
        self.linear_n_s += j.cast::<f64>();
        self.angular_n_m_s += (x - centre).cross(&j).cast::<f64>();
    }

    /// Adds sand of mass `mass_kg` met at `x` (m) with momentum `momentum` (N s), to a
    /// collider centred at `centre` (m): its momentum as an impulse at `x`, its mass, first
    /// moment and inertia to the sand met.
    #[inline]
    pub fn add_sand(
        &mut self,
        mass_kg: f32,
        momentum: Vector3<f32>,
        x: &Vector3<f32>,
        centre: &Vector3<f32>,
    ) {
        self.add_at(momentum, x, centre);
        self.sand_mass_kg += mass_kg as f64;
        let (m, arm) = (mass_kg as f64, (x - centre).cast::<f64>());
        self.sand_first_moment += arm * m;
        self.sand_inertia += (Matrix3::identity() * arm.norm_squared() - arm * arm.transpose()) * m;
    }
}

/// Affinity bit of collider `r`.
#[inline(always)]
pub fn affinity_bit(r: usize) -> u64 {
    1 << (2 * r)
}

/// Side bit of collider `r`.
#[inline(always)]
pub fn side_bit(r: usize) -> u64 {
    1 << (2 * r + 1)
}

/// The colliders (as affinity bits) both have affinity with but lie on different sides of.
#[inline(always)]
pub fn conflicts(node_bits: u64, particle_tags: u64) -> u64 {
    let shared = node_bits & particle_tags & AFFINITY_BITS;
    let sides_differ = ((node_bits ^ particle_tags) >> 1) & AFFINITY_BITS;
    shared & sides_differ
}

/// Whether a node and a particle may exchange momentum.
#[inline(always)]
pub fn compatible(node_bits: u64, particle_tags: u64) -> bool {
    conflicts(node_bits, particle_tags) == 0
}

/// The stencil's nodes: 3 x 3 x 3.
const STENCIL_NODES: usize = STENCIL * STENCIL * STENCIL;

/// The stencil's 27 nodes as `(arena index, weight, offset from the particle in cells)`, in
/// `(i, j, k)` order. Filled by plain loops into an array: as nested `flat_map`s the iterator
/// was not flattened by the compiler, and its adapters took 10 % of the shipped scene's time.
#[inline(always)]
pub fn stencil_nodes(
    s: &Stencil,
    base: [usize; 3],
) -> impl Iterator<Item = (usize, f32, Vector3<f32>)> {
    let mut nodes = [(0, 0.0, Vector3::zeros()); STENCIL_NODES];
    let mut n = 0;
    for i in 0..STENCIL {
        for j in 0..STENCIL {
            for k in 0..STENCIL {
                let a = node_in_arena(base[0] + i, base[1] + j, base[2] + k);
                nodes[n] = (a, s.weight(i, j, k), s.offset_cells(i, j, k));
                n += 1;
            }
        }
    }
    nodes.into_iter()
}

/// New tags of a particle from its old tags and its stencil's node colours: colliders that left
/// the stencil are dropped, those still in it keep their side, new ones get the side the
/// weighted stencil nodes vote for.
pub fn update_tags(old: u64, colours: &[NodeColour], s: &Stencil, base: [usize; 3]) -> u64 {
    // The colliders in range from the nodes' bits alone: most particles near a collider have
    // none in range and keep no tag, with no weight computed.
    let mut in_range = 0;
    for i in 0..STENCIL {
        for j in 0..STENCIL {
            let row = node_in_arena(base[0] + i, base[1] + j, base[2]);
            in_range |= colours[row].bits | colours[row + 1].bits | colours[row + 2].bits;
        }
    }
    let in_range = in_range & AFFINITY_BITS;
    let kept = old & (in_range | in_range << 1);
    let mut new = in_range & !old;
    let mut tags = kept;
    while new != 0 {
        let r = new.trailing_zeros() as usize / 2;
        new &= new - 1;
        let vote: f32 = stencil_nodes(s, base)
            .filter(|(a, _, _)| colours[*a].bits & affinity_bit(r) != 0)
            .map(|(a, w, _)| {
                if colours[a].bits & side_bit(r) != 0 {
                    w
                } else {
                    -w
                }
            })
            .sum();
        tags |= affinity_bit(r) | if vote >= 0.0 { side_bit(r) } else { 0 };
    }
    tags
}

/// The collider behind the first conflict, with the unit normal pointing to the particle's side
/// (zero if the node's closest collider is another one: the ghost then moves with the body).
#[inline]
pub fn conflict_normal(colour: &NodeColour, conflict: u64, tags: u64) -> (usize, Vector3<f32>) {
    let r = conflict.trailing_zeros() as usize / 2;
    let normal = if colour.closest as usize == r {
        let n = Vector3::from(colour.normal);
        if tags & side_bit(r) != 0 {
            n
        } else {
            -n
        }
    } else {
        Vector3::zeros()
    };
    (r, normal)
}

/// Ghost velocity a particle moving at `v` sees at an incompatible node at `x` (m/s).
#[inline]
pub fn ghost_velocity(
    v: Vector3<f32>,
    x: &Vector3<f32>,
    motion: &ColliderMotion,
    normal: Vector3<f32>,
) -> Vector3<f32> {
    let v_body = motion.velocity_at(x);
    if normal == Vector3::zeros() {
        return v_body;
    }
    friction_project(v, v_body, normal, motion.friction)
}

/// The particle's closest collider with its signed distance (m, positive on the particle's
/// tagged side) and the unit normal pointing to that side, interpolated from the stencil nodes
/// whose closest collider it is; None if the particle has no affinity with it.
pub fn wall_distance(
    tags: u64,
    colours: &[NodeColour],
    s: &Stencil,
    base: [usize; 3],
) -> Option<(usize, f32, Vector3<f32>)> {
    let (_, nearest) = stencil_nodes(s, base)
        .filter(|(a, _, _)| colours[*a].bits != 0)
        .map(|(a, w, _)| (w, a))
        .fold(
            (0.0f32, None),
            |best, (w, a)| {
                if w > best.0 {
                    (w, Some(a))
                } else {
                    best
                }
            },
        );
    let r = colours[nearest?].closest as usize;
    if tags & affinity_bit(r) == 0 {
        return None;
    }
    let (mut weight, mut distance, mut normal) = (0.0, 0.0, Vector3::zeros());
    for (a, w, _) in stencil_nodes(s, base) {
        let c = &colours[a];
        if c.bits & affinity_bit(r) != 0 && c.closest as usize == r {
            weight += w;
            distance += w * c.signed_distance_m;
            normal += w * Vector3::from(c.normal);
        }
    }
    let sign = if tags & side_bit(r) != 0 { 1.0 } else { -1.0 };
    let normal = normal.try_normalize(1e-12)?;
    Some((r, sign * distance / weight, sign * normal))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn compatibility_is_per_collider_side() {
        let mut node = NodeColour::default();
        node.set(3, true);
        node.set(7, false);
        // A particle with no tags is compatible with everything.
        assert!(compatible(node.bits, 0));
        // Same side of collider 3, no affinity with 7: compatible.
        assert!(compatible(node.bits, affinity_bit(3) | side_bit(3)));
        // Other side of collider 3: not.
        assert!(!compatible(node.bits, affinity_bit(3)));
        assert_eq!(conflicts(node.bits, affinity_bit(3)), affinity_bit(3));
        // Other side of collider 7 only.
        let tags = affinity_bit(3) | side_bit(3) | affinity_bit(7) | side_bit(7);
        assert_eq!(conflicts(node.bits, tags), affinity_bit(7));
        // Collider 31 uses the top bits.
        let mut high = NodeColour::default();
        high.set(31, true);
        assert!(!compatible(high.bits, affinity_bit(31)));
    }

    /// Sand at an offset moving with a translating light body: the common motion is that
    /// translation, with no spin (the linear and angular parts share one rigid motion).
    #[test]
    fn yield_is_one_rigid_motion() {
        let v = Vector3::new(0.3, 0.0, 0.0);
        let body = ColliderMotion {
            linear_m_s: v,
            angular_rad_s: Vector3::zeros(),
            centre_m: Vector3::zeros(),
            friction: 0.3,
            yield_inertia: Some(YieldInertia::free_body(0.002, 2e-8)),
            load_kick_m_s: Vector3::zeros(),
            load_kick_rad_s: Vector3::zeros(),
        };
        // 20 g of sand, 1 cm above the centre, moving at v.
        let (m, r) = (0.02f64, Vector3::new(0.0, 0.0, 0.01f64));
        let p = v.cast::<f64>() * m;
        let sand = ColliderImpulse {
            linear_n_s: p,
            angular_n_m_s: r.cross(&p),
            sand_mass_kg: m,
            sand_first_moment: r * m,
            sand_inertia: (Matrix3::identity() * r.norm_squared() - r * r.transpose()) * m,
        };
        let y = body.yielded(Some(&sand));
        assert!((y.linear_m_s - v).norm() < 1e-6, "{}", y.linear_m_s);
        assert!(y.angular_rad_s.norm() < 1e-4, "{}", y.angular_rad_s);
        // Sand at rest: the common motion keeps momentum and angular momentum.
        let still = ColliderImpulse {
            linear_n_s: Vector3::zeros(),
            angular_n_m_s: Vector3::zeros(),
            ..sand
        };
        let y = body.yielded(Some(&still));
        let (v_s, w_s) = (y.linear_m_s.cast::<f64>(), y.angular_rad_s.cast::<f64>());
        let momentum = v_s * (0.002 + m) - r.cross(&w_s) * m;
        assert!(
            (momentum - v.cast::<f64>() * 0.002).norm() < 1e-9,
            "{momentum}"
        );
        let angular = w_s * 2e-8 + (r * m).cross(&v_s) + still.sand_inertia * w_s;
        assert!(angular.norm() < 1e-9, "{angular}");
        assert!(y.linear_m_s.norm() < v.norm(), "the light body slows down");
        // A body that does not yield keeps its motion.
        let heavy = ColliderMotion {
            yield_inertia: None,
            ..body
        };
        assert_eq!(heavy.yielded(Some(&sand)), heavy);
    }

    /// Two 1 kg parts 0.2 m apart along x: about the first one's centre the pair has 2 kg, a
    /// first moment of 0.2 kg m along x and, beyond the parts' own inertia, 0.04 kg m^2 about y
    /// and z from the second part, none about x.
    #[test]
    fn parts_add_by_the_parallel_axis_theorem() {
        let own = Matrix3::from_diagonal(&Vector3::new(1e-3, 2e-3, 3e-3));
        let (a, b) = (Vector3::new(0.1, 0.0, 0.0), Vector3::new(0.3, 0.0, 0.0));
        let pair = YieldInertia::of_parts([(1.0, a, own), (1.0, b, own)], &a);
        let expected = YieldInertia::rigid(
            2.0,
            &Vector3::new(0.2, 0.0, 0.0),
            &(own * 2.0 + Matrix3::from_diagonal(&Vector3::new(0.0, 0.04, 0.04))),
        );
        assert!(
            (pair.spatial() - expected.spatial()).norm() < 1e-12,
            "{}",
            pair.spatial()
        );
    }

    /// A leg held by its motor to an 85 g robot whose centre of mass sits 3 cm above the leg's
    /// centre meets 20 g of sand at rest: body and sand keep their momentum and angular momentum
    /// about the leg's centre, and the leg keeps most of its motion, where alone (2 g) it would
    /// nearly stop: with its own mass it could carry only a 40th of the load per substep.
    #[test]
    fn a_leg_yields_with_the_robot_it_is_held_to() {
        let v = Vector3::new(0.05, 0.0, -0.3f32);
        let (m_r, e) = (0.085f64, Vector3::new(0.0, 0.0, 0.03f64));
        let centred = Matrix3::from_diagonal(&Vector3::new(1e-4, 2e-4, 2e-4));
        let robot = YieldInertia::rigid(
            m_r,
            &(e * m_r),
            &(centred + (Matrix3::identity() * e.norm_squared() - e * e.transpose()) * m_r),
        );
        let leg = ColliderMotion {
            linear_m_s: v,
            angular_rad_s: Vector3::new(0.0, 2.0, 0.0),
            centre_m: Vector3::zeros(),
            friction: 0.3,
            yield_inertia: Some(robot),
            load_kick_m_s: Vector3::zeros(),
            load_kick_rad_s: Vector3::zeros(),
        };
        let (m, r) = (0.02f64, Vector3::new(0.004, 0.0, -0.01f64));
        let sand = ColliderImpulse {
            linear_n_s: Vector3::zeros(),
            angular_n_m_s: Vector3::zeros(),
            sand_mass_kg: m,
            sand_first_moment: r * m,
            sand_inertia: (Matrix3::identity() * r.norm_squared() - r * r.transpose()) * m,
        };
        let y = leg.yielded(Some(&sand));
        // Momenta about the leg's centre, written out rather than through `spatial`, of a point
        // mass `mass` at `at` and inertia `own` about it, moving rigidly with `(v, w)` given at
        // the leg's centre: p = mass (v + w x at), L = own w + at x p.
        let momenta = |c: &ColliderMotion, mass: f64, at: &Vector3<f64>, own: &Matrix3<f64>| {
            let (v, w) = (c.linear_m_s.cast::<f64>(), c.angular_rad_s.cast::<f64>());
            let p = (v + w.cross(at)) * mass;
            (p, own * w + at.cross(&p))
        };
        // Before: the robot moving with the leg, the sand at rest; after: both moving with `y`.
        let (p_robot, l_robot) = momenta(&leg, m_r, &e, &centred);
        let (p_after, l_after) = {
            let (p_r, l_r) = momenta(&y, m_r, &e, &centred);
            let (p_s, l_s) = momenta(&y, m, &r, &Matrix3::zeros());
            (p_r + p_s, l_r + l_s)
        };
        // The changed motion is stored in f32.
        assert!(
            (p_after - p_robot).norm() < 1e-6 * p_robot.norm(),
            "{p_after} vs {p_robot}"
        );
        assert!(
            (l_after - l_robot).norm() < 1e-6 * l_robot.norm(),
            "{l_after} vs {l_robot}"
        );
        // The leg's velocity where it meets the sand.
        let contact = r.cast::<f32>();
        let pushing = leg.velocity_at(&contact).norm();
        assert!(
            y.velocity_at(&contact).norm() > 0.75 * pushing,
            "held to the robot the leg keeps its motion: {}",
            y.velocity_at(&contact)
        );
        let alone = ColliderMotion {
            yield_inertia: Some(YieldInertia::free_body(0.002, 2e-8)),
            load_kick_m_s: Vector3::zeros(),
            load_kick_rad_s: Vector3::zeros(),
            ..leg
        };
        let stopped = alone.yielded(Some(&sand)).velocity_at(&contact);
        assert!(stopped.norm() < 0.15 * pushing, "alone it stops: {stopped}");
    }

    #[test]
    fn tags_vote_once_then_persist() {
        use super::super::grid::ARENA_NODES;
        // A sheet at z = 2.5 cells: nodes with z <= 2 below (negative side), z >= 3 above.
        let mut colours = vec![NodeColour::default(); ARENA_NODES];
        for x in 0..6 {
            for y in 0..6 {
                for z in 0..6 {
                    let c = &mut colours[node_in_arena(x, y, z)];
                    c.set(0, z >= 3);
                    c.signed_distance_m = z as f32 - 2.5;
                    c.normal = [0.0, 0.0, 1.0];
                }
            }
        }
        // A particle at z = 2.2 cells: its stencil nodes z = 1, 2, 3 vote negative.
        let s = Stencil::new(Vector3::new(2.3, 2.3, 2.2));
        let base = [0, 1, 2].map(|a| s.base[a] as usize);
        let tags = update_tags(0, &colours, &s, base);
        assert_eq!(tags, affinity_bit(0));
        // The same particle seen above the sheet keeps its side (no tunnelling)...
        let above = Stencil::new(Vector3::new(2.3, 2.3, 2.8));
        let above_base = [0, 1, 2].map(|a| above.base[a] as usize);
        assert_eq!(update_tags(tags, &colours, &above, above_base), tags);
        // ...while a new particle there votes positive.
        let fresh = update_tags(0, &colours, &above, above_base);
        assert_eq!(fresh, affinity_bit(0) | side_bit(0));
        // Leaving the band clears the tag.
        assert_eq!(
            update_tags(tags, &vec![NodeColour::default(); ARENA_NODES], &s, base),
            0
        );
        // The interpolated distance is the particle's own (the field is linear), and the
        // normal points to its tagged side.
        let (r, d, n) = wall_distance(tags, &colours, &s, base).unwrap();
        assert_eq!(r, 0);
        assert!((d - 0.3).abs() < 1e-5, "{d}");
        assert_eq!(n, Vector3::new(0.0, 0.0, -1.0));
        let (_, d, _) = wall_distance(tags, &colours, &above, above_base).unwrap();
        assert!((d + 0.3).abs() < 1e-5, "wrong side by 0.3 cells: {d}");
    }
}
