//! G2P: each particle gathers its new velocity and velocity gradient from its 27 stencil nodes
//! (Hu et al. 2018, eq. 17 and 25), is advected, and keeps its affine matrix for the next P2G
//! (APIC) or drops it (PIC). Near colliders, CPIC reads a ghost velocity at the nodes across a
//! collider and pushes back a particle found slightly on the wrong side. The deformation
//! gradient and the stress follow in `particle_update.rs`. With AFLIP the particle's velocity
//! also keeps a share of its own deviation from the grid's (Fei et al. 2021).

use nalgebra::{Matrix3, Vector3};
use std::sync::atomic::Ordering;

use rayon::prelude::*;

use super::cpic_grid::{add_impulses, CpicParticle, CpicTransfer, GridColours};
use super::settings::KeptShares;
use super::{local_base, scale_columns, split_runs, CpicBand, Solver, Transfer};
use crate::mpm::cpic::{
    conflict_normal, conflicts, ghost_velocity, stencil_nodes, wall_distance, ColliderImpulse,
    ColliderMotion, PENALTY_MAX_CELLS, PENALTY_MIN_CELLS,
};
use crate::mpm::grid::{node_in_arena, ArenaSlot, Block, ParticleBlock, SparseGrid, ARENA_NODES};
use crate::mpm::kernel::{Kernel, KernelKind, LinearKernel, QuadraticBsplineKernel, Stencil};
use crate::mpm::particles::Particles;
use crate::mpm::simd::{array3, Node, NodePair, WithNodes, F4};

impl Solver {
    /// G2P over the awake particle blocks: velocity, velocity gradient (kept in
    /// `self.velocity_gradient` for the particle update), advection, the affine matrix, and
    /// the clamp into the domain, and the penalty against colliders that yield
    /// ([`settle_penalty`]). Returns the momentum CPIC handed to each collider, and, if a stop
    /// request left blocks out, which blocks moved.
    pub(super) fn grid_to_particle(
        &mut self,
        dt: f32,
        colliders: &[ColliderMotion],
    ) -> (Vec<ColliderImpulse>, Option<Vec<bool>>) {
        let context = G2pContext {
            grid: &self.grid,
            colours: &self.colours,
            colliders,
            slots: &self.arena_slots,
            dt,
            dx: self.settings.dx,
            lo: self.bounds[0],
            hi: self.bounds[1],
            affine_transfer: self.settings.transfer != Transfer::Pic,
            band_as_bulk: self.settings.cpic_band == CpicBand::Bulk,
            flip: (self.settings.transfer == Transfer::Aflip).then_some(Flip {
                transferred_velocity: &self.transferred_velocity,
                shares: self.settings.kept_shares(dt),
            }),
            kernel: self.settings.kernel,
        };
        let blocks = &self.grid.particle_blocks;
        let instruction_set = self.instruction_set;
        let stop = &*self.stop;
        self.velocity_gradient
            .resize(self.particles.len(), Matrix3::zeros());
        let views = G2pView::split(&mut self.particles, &mut self.velocity_gradient, blocks);
        // A block that sees a stop request is left as it was (None).
        let per_block: Vec<_> = views
            .into_par_iter()
            .zip(blocks.par_iter())
            .map(|(view, pb)| {
                (!stop.load(Ordering::Relaxed)).then(|| {
                    instruction_set.dispatch_nodes(G2pBlock {
                        cx: &context,
                        view,
                        pb,
                    })
                })
            })
            .collect();
        let moved = per_block
            .iter()
            .any(Option::is_none)
            .then(|| per_block.iter().map(Option::is_some).collect());
        let mut impulses = Vec::new();
        let mut contacts = Vec::new();
        for (block_impulses, block_contacts) in per_block.into_iter().flatten() {
            impulses = add_impulses(impulses, &block_impulses);
            contacts.extend(block_contacts);
        }
        let particles = PenaltyParticles {
            position: &self.particles.position,
            velocity: &mut self.particles.velocity,
            mass: &self.particles.mass,
        };
        settle_penalty(particles, colliders, &contacts, &mut impulses);
        (impulses, moved)
    }
}

/// What G2P reads besides the particles.
struct G2pContext<'a> {
    grid: &'a SparseGrid,
    colours: &'a GridColours,
    colliders: &'a [ColliderMotion],
    slots: &'a [ArenaSlot; ARENA_NODES],
    /// Substep (s).
    dt: f32,
    /// Grid spacing (m).
    dx: f32,
    /// The box particles are clamped into (m): the domain, or its x window.
    lo: Vector3<f32>,
    hi: Vector3<f32>,
    /// Keep the affine matrix for the next P2G (APIC, AFLIP) or not (PIC).
    affine_transfer: bool,
    /// Particles in the CPIC band transfer as the bulk does (`CpicBand::Bulk`), not as PIC.
    band_as_bulk: bool,
    /// AFLIP's FLIP increment, or none (APIC, PIC).
    flip: Option<Flip<'a>>,
    kernel: Kernel,
}

/// What AFLIP's velocity update reads besides the updated grid.
#[derive(Clone, Copy)]
struct Flip<'a> {
    /// Node velocities from the transfer alone of the particles that keep a deviation (m/s;
    /// those away from colliders, and with `CpicBand::Bulk` those near one over their
    /// compatible nodes), each weighted by the share it keeps, by grid block: the grid
    /// velocity the particle deviates from.
    /// (Measured against the node velocity with the stress impulse in, a particle at rest
    /// kept `-a tau` for the stress's acceleration `a`, and the sand under gravity pressed
    /// itself down with several g.)
    transferred_velocity: &'a [Block],
    /// Shares of the particle's own deviation kept this substep, `exp(-dt / tau)`, away from
    /// colliders and in the CPIC band (`CpicBand::Bulk`).
    shares: KeptShares,
}

/// What an AFLIP particle keeps of its deviation from the grid: velocity (m/s) and affine
/// field (1/s), the particle's old value minus the grid's from the transfer alone gathered at the
/// particle (Fei et al. 2021 keep the velocity's; the affine field's is kept here too).
///
/// Angular momentum: APIC's round trip keeps `sum m (x x v + skew(C D))` (Jiang et al. 2015),
/// so keeping the velocity's deviation and the affine field's rotation with the same share adds
/// none. Keeping only the velocity's (as Fei et al. do) moved the spinning cube of
/// `tests/stability.rs` by 2.4 % in 0.2 s.
///
/// The affine field's strain rate (its symmetric part) is kept with the share squared: it
/// relaxes in half the time. Measured on the collapse of `tests/column_collapse.rs`
/// (`docs/speed-vs-accuracy.md`): kept like the rest, stiff sand (E = 3.5 MPa) threw grains
/// about the box; dropped at once, the runout followed the substep count again (11 %).
#[derive(Clone, Copy)]
struct KeptDeviation {
    velocity: Vector3<f32>,
    affine: Matrix3<f32>,
}

impl KeptDeviation {
    /// Keeps `blend` of the velocity deviation `velocity` and of the rotation in the affine
    /// deviation `affine`, `blend^2` of its strain rate; `inverse_moment` = `D^-1` (1/m^2).
    fn new(
        blend: f32,
        velocity: Vector3<f32>,
        affine: Matrix3<f32>,
        inverse_moment: &Vector3<f32>,
    ) -> Self {
        // Split C D (m^2/s, D diagonal) so that the rotation carries all the angular momentum.
        let affine_moment = scale_columns(&affine, &inverse_moment.map(|d| 1.0 / d));
        let rotation = (affine_moment - affine_moment.transpose()) * 0.5;
        let strain_rate = (affine_moment + affine_moment.transpose()) * 0.5;
        KeptDeviation {
            velocity: velocity * blend,
            affine: scale_columns(&((rotation + strain_rate * blend) * blend), inverse_moment),
        }
    }

    /// Keeps `blend` of the velocity deviation `velocity` only (in the CPIC band, where the
    /// affine field is the one CPIC's gather gives, ghosts included).
    fn of_velocity(blend: f32, velocity: Vector3<f32>) -> Self {
        KeptDeviation {
            velocity: velocity * blend,
            affine: Matrix3::zeros(),
        }
    }

    /// Adds to the affine field the spin that balances advecting with the PIC velocity
    /// `v_pic` (m/s) over `dt` (s): the kept velocity's moment about the moved particle differs
    /// by `dt v_pic x dv`, given back as a rotation `omega` of the affine field, whose moment
    /// is `(D_yy + D_zz) omega_x` (and alike), with `inverse_moment` = `D^-1` (1/m^2).
    fn with_spin_for_advection(
        mut self,
        v_pic: &Vector3<f32>,
        dt: f32,
        inverse_moment: &Vector3<f32>,
    ) -> Self {
        let moment = inverse_moment.map(|d| 1.0 / d);
        let lost = v_pic.cross(&self.velocity) * dt;
        let omega = Vector3::new(
            lost.x / (moment.y + moment.z),
            lost.y / (moment.z + moment.x),
            lost.z / (moment.x + moment.y),
        );
        self.affine -= omega.cross_matrix();
        self
    }
}

/// G2P of one particle block, as the work of
/// [`crate::mpm::simd::InstructionSet::dispatch_nodes`]:
/// compiled with the instruction set's features (VEX encoding with AVX2; the same bits, as no
/// product is fused).
/// Only what is inlined gets them: the CPIC band's `gather_cpic` and `push_back`
/// (`#[inline(never)]`) stay compiled for the baseline; inlined, they (and the compatible
/// gather since folded into `gather_cpic`) changed the shipped scene's wall time by 0.99
/// (0.98-1.04), 5 pairs.
struct G2pBlock<'a> {
    cx: &'a G2pContext<'a>,
    view: G2pView<'a>,
    pb: &'a ParticleBlock,
}

impl WithNodes for G2pBlock<'_> {
    type Output = (Vec<ColliderImpulse>, Vec<PenaltyContact>);
    #[inline(always)]
    fn run<P: NodePair>(self) -> Self::Output {
        match self.cx.kernel {
            Kernel::QuadraticBspline => {
                grid_to_particle_block::<P, QuadraticBsplineKernel>(self.cx, self.view, self.pb)
            }
            Kernel::Linear => {
                grid_to_particle_block::<P, LinearKernel>(self.cx, self.view, self.pb)
            }
        }
    }
}

/// G2P of one particle block: loads its 6x6x6 arena of node velocities once, then per particle
/// gathers v and C (with ghost velocities near colliders), advects, pushes back and clamps.
/// Returns the CPIC impulses on the colliders (empty where no particle is near one) and the
/// penalty contacts with colliders that yield, to be settled after G2P. Compiled for the
/// kernel `K`, so that what depends on the kernel's constant moment alone leaves the loop.
#[inline(always)]
fn grid_to_particle_block<P: NodePair, K: KernelKind>(
    cx: &G2pContext,
    view: G2pView,
    pb: &ParticleBlock,
) -> (Vec<ColliderImpulse>, Vec<PenaltyContact>) {
    let G2pContext {
        grid,
        colours,
        colliders,
        slots,
        dt,
        dx,
        lo,
        hi,
        affine_transfer,
        band_as_bulk,
        flip,
        kernel: _,
    } = *cx;
    let arena = load_arena(&grid.blocks, slots, pb);
    let arena_transferred = flip.map(|f| load_arena(f.transferred_velocity, slots, pb));
    // Away from colliders AFLIP gathers both grids in one pass. (No closure: one the
    // compiler does not inline runs without the instruction set's features.)
    let arena_pairs = match &arena_transferred {
        Some(transferred) => {
            let mut pairs = [P::splat(0.0); ARENA_NODES];
            for (a, pair) in pairs.iter_mut().enumerate() {
                *pair = P::from_halves(arena[a], transferred[a]);
            }
            Some(pairs)
        }
        None => None,
    };
    let mut impulses = Vec::new();
    let mut contacts = Vec::new();
    let colour_arena = colours.arena(pb, slots);
    for i in 0..view.position.len() {
        let x = view.position[i];
        let s = K::stencil(grid.to_grid(&x));
        let base = local_base(&s, pb);
        let tags = view.cpic_tags[i];
        // Near a collider: CPIC's transfer over the compatible nodes, ghosts elsewhere.
        let cpic = colour_arena
            .as_ref()
            .filter(|_| tags != 0)
            .map(|colour| CpicTransfer {
                colours: &colour[..],
                colliders,
                dx,
            });
        let particle = CpicParticle {
            x,
            v: view.velocity[i],
            mass: view.mass[i],
            tags,
        };
        // The grid's velocity and gradient sums, and with AFLIP the transferred grid's: as
        // node pairs away from colliders, over the compatible nodes in the band (with
        // `CpicBand::Bulk`).
        let ((mut v, b), bulk_transferred, band_transferred) = match (&cpic, &arena_pairs) {
            (Some(cx), _) => {
                if impulses.is_empty() {
                    impulses = vec![ColliderImpulse::default(); colliders.len()];
                }
                let transferred = arena_transferred.as_ref().filter(|_| band_as_bulk);
                let (gathered, compatible) =
                    gather_cpic(&arena, transferred, cx, &s, base, &particle, &mut impulses);
                (gathered, None, compatible)
            }
            (None, Some(pairs)) => {
                let (grid, transferred) = gather_pair(pairs, &s, base);
                (grid, Some(transferred), None)
            }
            (None, None) => (gather(&arena, &s, base), None, None),
        };
        // C_p = sum w v_i (x_i - x_p)^T D^-1, with offsets in cells.
        let c = scale_columns(&b, &(s.inverse_moment / dx));
        // AFLIP: the particle keeps a share of how its velocity (and, away from colliders, its
        // affine field) differed from the grid's its transfer gave, before forces; in the CPIC
        // band only with `CpicBand::Bulk`.
        // (A `match`, not a closure: a closure the compiler does not inline runs without the
        // instruction set's features, and this one, with its gather, took 14 % of the shipped
        // scene's time.)
        let kept = match flip {
            Some(f) if cpic.is_none() || band_as_bulk => {
                let inverse_moment = s.inverse_moment / (dx * dx);
                let deviation = match (bulk_transferred, band_transferred) {
                    (Some((v_transferred, b_transferred)), _) => {
                        let c_transferred = scale_columns(&b_transferred, &(s.inverse_moment / dx));
                        KeptDeviation::new(
                            f.shares.bulk,
                            view.velocity[i] - v_transferred,
                            view.affine[i] - c_transferred,
                            &inverse_moment,
                        )
                    }
                    (None, Some(compatible)) => {
                        let deviation = compatible.deviation(&particle, &view.affine[i], dx);
                        KeptDeviation::of_velocity(f.shares.band, deviation)
                    }
                    (None, None) => unreachable!(
                        "with AFLIP a particle gathers the transferred grid too: as a node pair \
                         in the bulk, over its compatible nodes in the band"
                    ),
                };
                Some(deviation.with_spin_for_advection(&v, dt, &inverse_moment))
            }
            _ => None,
        };
        // Advected with the grid's (PIC) velocity (Fei et al. 2021).
        let mut x_new = x + v * dt;
        // In the CPIC band with `CpicBand::Pic`: no affine field (plain PIC).
        view.affine[i] = if affine_transfer && (cpic.is_none() || band_as_bulk) {
            kept.map_or(c, |k| c + k.affine)
        } else {
            Matrix3::zeros()
        };
        if let Some(k) = kept {
            v += k.velocity;
        }
        if let Some(cx) = &cpic {
            let contact = push_back(cx, &s, base, &particle, &mut x_new, &mut v, &mut impulses);
            if let Some((collider, normal)) = contact {
                contacts.push(PenaltyContact {
                    particle: pb.start + i,
                    collider,
                    normal,
                });
            }
        }
        view.position[i] = x_new.sup(&lo).inf(&hi);
        view.velocity[i] = v;
        view.velocity_gradient[i] = c;
    }
    (impulses, contacts)
}

/// The 6x6x6 arena of node vectors around particle block `pb`, from `blocks` (the grid's, or
/// a per-node array in the same block order).
fn load_arena(
    blocks: &[Block],
    slots: &[ArenaSlot; ARENA_NODES],
    pb: &ParticleBlock,
) -> [F4; ARENA_NODES] {
    let mut arena = [F4::splat(0.0); ARENA_NODES];
    for (a, slot) in slots.iter().enumerate() {
        arena[a] = F4::from_array(
            blocks[pb.arena_blocks[slot.block as usize] as usize][slot.node as usize],
        );
    }
    arena
}

/// `(sum w_i v_i, sum w_i v_i d_i^T)` (m/s, m/s in cells) gathered at a particle.
type VelocityAndGradient = (Vector3<f32>, Matrix3<f32>);

/// Gathers `(sum w_i v_i, sum w_i v_i d_i^T)` over the 27 stencil nodes, `d_i` in cells. Arena
/// nodes are SIMD vectors `[v_x, v_y, v_z, m]`; the mass lane is summed along and ignored.
#[inline(always)]
fn gather(arena: &[F4; ARENA_NODES], s: &Stencil, base: [usize; 3]) -> VelocityAndGradient {
    velocity_and_gradient(gather_sums(arena, s, base), &s.fx)
}

/// [`gather`] from the grid and AFLIP's transferred grid at once (one node pair per node):
/// `(grid, transferred)`.
#[inline(always)]
fn gather_pair<P: NodePair>(
    arena: &[P; ARENA_NODES],
    s: &Stencil,
    base: [usize; 3],
) -> (VelocityAndGradient, VelocityAndGradient) {
    let [v, by_i, by_j, by_k] = gather_sums(arena, s, base);
    (
        velocity_and_gradient([v.low(), by_i.low(), by_j.low(), by_k.low()], &s.fx),
        velocity_and_gradient([v.high(), by_i.high(), by_j.high(), by_k.high()], &s.fx),
    )
}

/// `[sum w v, sum w v i, sum w v j, sum w v k]` over the 27 stencil nodes, `(i, j, k)` the
/// node's index in the stencil: the outer product `sum w v d^T` is summed per axis and
/// shifted by the particle's offset in [`velocity_and_gradient`].
#[inline(always)]
fn gather_sums<N: Node>(arena: &[N; ARENA_NODES], s: &Stencil, base: [usize; 3]) -> [N; 4] {
    let zero = N::splat(0.0);
    let w_k = array3!(k => N::splat(s.weights[2][k]));
    let (mut v, mut by_i, mut by_j, mut by_k) = (zero, zero, zero, zero);
    for i in 0..3 {
        let mut v_i = zero;
        for j in 0..3 {
            let w_ij = N::splat(s.weights[0][i] * s.weights[1][j]);
            let row = node_in_arena(base[0] + i, base[1] + j, base[2]);
            let v0 = arena[row] * w_k[0];
            let v1 = arena[row + 1] * w_k[1];
            let v2 = arena[row + 2] * w_k[2];
            let v_ij = (v0 + v1 + v2) * w_ij;
            by_k = by_k + (v1 + v2 + v2) * w_ij;
            v_i = v_i + v_ij;
            by_j = by_j + v_ij * N::splat(j as f32);
        }
        v = v + v_i;
        by_i = by_i + v_i * N::splat(i as f32);
    }
    [v, by_i, by_j, by_k]
}

/// `(sum w v, sum w v d^T)` from [`gather_sums`]: `sum w v (i, j, k)^T - (sum w v) fx^T`, with
/// `fx` the particle's offset from the stencil's first node (cells).
#[inline(always)]
fn velocity_and_gradient(sums: [F4; 4], fx: &Vector3<f32>) -> VelocityAndGradient {
    let column = |c: F4| {
        let [x, y, z, _] = c.to_array();
        Vector3::new(x, y, z)
    };
    let [v, by_i, by_j, by_k] = sums.map(column);
    (
        v,
        Matrix3::from_columns(&[by_i, by_j, by_k]) - v * fx.transpose(),
    )
}

/// [`gather`] with CPIC: an incompatible node contributes the ghost velocity instead of its own.
/// With `transferred` (AFLIP's transferred grid, `CpicBand::Bulk`) it also sums that grid over
/// the compatible nodes ([`CompatibleTransfer`]), in the same pass.
#[inline(never)]
fn gather_cpic(
    arena: &[F4; ARENA_NODES],
    transferred: Option<&[F4; ARENA_NODES]>,
    cx: &CpicTransfer,
    s: &Stencil,
    base: [usize; 3],
    p: &CpicParticle,
    impulses: &mut [ColliderImpulse],
) -> (VelocityAndGradient, Option<CompatibleTransfer>) {
    let (mut v, mut b) = (Vector3::zeros(), Matrix3::zeros());
    // The transferred grid with its running compatible sum.
    let mut compatible = transferred.map(|arena| {
        let sum = CompatibleTransfer {
            weighted_velocity: Vector3::zeros(),
            weight: 0.0,
            weighted_offset_cells: Vector3::zeros(),
        };
        (arena, sum)
    });
    for (a, w, d) in stencil_nodes(s, base) {
        let colour = &cx.colours[a];
        let conflict = conflicts(colour.bits, p.tags);
        let v_node = if conflict == 0 {
            if let Some((transferred, sum)) = &mut compatible {
                let [x, y, z, _] = transferred[a].to_array();
                sum.weighted_velocity += Vector3::new(x, y, z) * w;
                sum.weight += w;
                sum.weighted_offset_cells += d * w;
            }
            let [x, y, z, _] = arena[a].to_array();
            Vector3::new(x, y, z)
        } else {
            let x_node = p.x + d * cx.dx;
            let (r, normal) = conflict_normal(colour, conflict, p.tags);
            let motion = &cx.colliders[r];
            let ghost = ghost_velocity(p.v, &x_node, motion, normal);
            impulses[r].add_at(-ghost * (w * p.mass), &x_node, &motion.centre_m);
            ghost
        };
        v += v_node * w;
        b += v_node * w * d.transpose();
    }
    ((v, b), compatible.map(|(_, sum)| sum))
}

/// AFLIP's transferred grid seen by a particle in the CPIC band, summed over its compatible
/// nodes only (the nodes its P2G reached).
struct CompatibleTransfer {
    /// `sum w v~_i` (m/s).
    weighted_velocity: Vector3<f32>,
    /// `sum w`, the share of the stencil that is compatible.
    weight: f32,
    /// `sum w d_i`, `d_i` the node's offset from the particle in cells.
    weighted_offset_cells: Vector3<f32>,
}

impl CompatibleTransfer {
    /// The particle's deviation from the transferred grid (m/s), measured so that the band's
    /// deviations and the bulk's sum to zero momentum: what the particle's P2G left on its
    /// compatible nodes per unit mass, `W v_p + C_p sum w (x_i - x_p)`, less what those nodes
    /// give back, `sum w v~_i`. Summed over particles with their masses, both parts are
    /// `sum_i m~_i v~_i`. Away from colliders (`W` = 1, `sum w d` = 0) this is `v_p - v~(x_p)`.
    fn deviation(&self, p: &CpicParticle, affine: &Matrix3<f32>, dx: f32) -> Vector3<f32> {
        p.v * self.weight + affine * (self.weighted_offset_cells * dx) - self.weighted_velocity
    }
}

/// CPIC penalty: a particle that ended up between [`PENALTY_MIN_CELLS`] and
/// [`PENALTY_MAX_CELLS`] on the wrong side of its closest collider is put back on the surface.
/// Against a collider that does not yield (one-way, kinematic, fixed) it also loses its inward
/// velocity relative to the collider, which takes the reaction. Against one that yields, the
/// contact is returned, to be settled with the collider after G2P ([`settle_penalty`]).
#[inline(never)]
fn push_back(
    cx: &CpicTransfer,
    s: &Stencil,
    base: [usize; 3],
    p: &CpicParticle,
    x_new: &mut Vector3<f32>,
    v: &mut Vector3<f32>,
    impulses: &mut [ColliderImpulse],
) -> Option<(usize, Vector3<f32>)> {
    let (r, distance, normal) = wall_distance(p.tags, cx.colours, s, base)?;
    let distance = distance + normal.dot(&(*x_new - p.x));
    if distance >= -PENALTY_MIN_CELLS * cx.dx || distance <= -PENALTY_MAX_CELLS * cx.dx {
        return None;
    }
    *x_new -= normal * distance;
    let motion = &cx.colliders[r];
    // (An invalid inertia yields nothing in `ColliderMotion::yielded`: the settled penalty is
    // then this one.)
    if motion.yield_inertia.is_some() {
        return Some((r, normal));
    }
    let dv = stop_inward(v, motion.velocity_at(x_new), &normal);
    impulses[r].add_at(-dv * p.mass, x_new, &motion.centre_m);
    None
}

/// Removes from `v` its velocity into a surface moving at `surface_velocity` (unit `normal`
/// pointing out of it); returns the change (zero if `v` does not approach).
fn stop_inward(
    v: &mut Vector3<f32>,
    surface_velocity: Vector3<f32>,
    normal: &Vector3<f32>,
) -> Vector3<f32> {
    let approach = (*v - surface_velocity).dot(normal);
    let dv = -approach.min(0.0) * normal;
    *v += dv;
    dv
}

/// The particle arrays [`settle_penalty`] reads and writes.
struct PenaltyParticles<'a> {
    position: &'a [Vector3<f32>],
    velocity: &'a mut [Vector3<f32>],
    mass: &'a [f32],
}

/// A particle put back on the surface of a collider that yields.
#[derive(Clone, Copy, Debug)]
struct PenaltyContact {
    /// Index in the particle arrays.
    particle: usize,
    collider: usize,
    /// Unit normal of the collider's surface, pointing to the particle's side.
    normal: Vector3<f32>,
}

/// The penalty against colliders that yield, as one more exchange. The particles put back on a
/// collider's surface in this substep (`contacts`) and the collider, at the motion it took in
/// the exchange with its inertia, share one rigid motion ([`ColliderMotion::yielded`]); each
/// particle then loses its inward velocity relative to that motion, and the collider takes the
/// reaction. Where the particles approach along one normal, the collider's velocity thus
/// changes by the motion it shares with them and not past them (unit test below). The shared
/// motion is not exact otherwise: it counts every contact's whole momentum, separating and
/// sliding ones included, while only inward normal velocity is then removed, so a contact
/// moving away fast, or contacts on differently facing parts of the surface, can still move
/// the collider past some of them (not seen in the robot runs; counting only the approaching
/// contacts' normal momentum is the next refinement). (Stopping each particle against the
/// collider's own motion, as for colliders that do not yield, hands a light leg the reaction of
/// every particle in full: a few 0.4 g particles against a 1.3 g leg spun it back past them,
/// the next penalty came from the other side, several times larger, and the straight-leg robot
/// blew up at landing; `docs/stability.md`, "The robot that turns over".)
fn settle_penalty(
    particles: PenaltyParticles,
    colliders: &[ColliderMotion],
    contacts: &[PenaltyContact],
    impulses: &mut Vec<ColliderImpulse>,
) {
    if contacts.is_empty() {
        return;
    }
    let PenaltyParticles {
        position,
        velocity,
        mass,
    } = particles;
    if impulses.len() < colliders.len() {
        impulses.resize(colliders.len(), ColliderImpulse::default());
    }
    for (r, motion) in colliders.iter().enumerate() {
        let mine = || contacts.iter().filter(move |c| c.collider == r);
        let mut met = ColliderImpulse::default();
        for c in mine() {
            let (x, v, m) = (position[c.particle], velocity[c.particle], mass[c.particle]);
            met.add_sand(m, v * m, &x, &motion.centre_m);
        }
        if met.sand_mass_kg == 0.0 {
            continue;
        }
        // The kick is in the collider's motion where the exchange met sand; where it met none
        // the motion is the collider's own, without the kick, as in the old penalty.
        let shared = ColliderMotion {
            load_kick_m_s: Vector3::zeros(),
            load_kick_rad_s: Vector3::zeros(),
            ..*motion
        }
        .yielded(Some(&met));
        for c in mine() {
            let x = position[c.particle];
            let dv = stop_inward(&mut velocity[c.particle], shared.velocity_at(&x), &c.normal);
            impulses[r].add_at(-dv * mass[c.particle], &x, &motion.centre_m);
        }
    }
}

/// Mutable views of the particle arrays G2P writes, for one particle block.
struct G2pView<'a> {
    position: &'a mut [Vector3<f32>],
    velocity: &'a mut [Vector3<f32>],
    affine: &'a mut [Matrix3<f32>],
    velocity_gradient: &'a mut [Matrix3<f32>],
    mass: &'a [f32],
    cpic_tags: &'a [u64],
}

impl<'a> G2pView<'a> {
    fn split(
        p: &'a mut Particles,
        velocity_gradient: &'a mut [Matrix3<f32>],
        blocks: &[ParticleBlock],
    ) -> Vec<G2pView<'a>> {
        let mut position = split_runs(&mut p.position, blocks).into_iter();
        let mut velocity = split_runs(&mut p.velocity, blocks).into_iter();
        let mut affine = split_runs(&mut p.affine, blocks).into_iter();
        let mut velocity_gradient = split_runs(velocity_gradient, blocks).into_iter();
        let (mass, cpic_tags) = (&p.mass[..], &p.cpic_tags[..]);
        blocks
            .iter()
            .map(|pb| G2pView {
                position: position.next().unwrap(),
                velocity: velocity.next().unwrap(),
                affine: affine.next().unwrap(),
                velocity_gradient: velocity_gradient.next().unwrap(),
                mass: &mass[pb.start..pb.end],
                cpic_tags: &cpic_tags[pb.start..pb.end],
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mpm::cpic::YieldInertia;

    /// Seven 0.4 g particles pushed back onto a free 1.3 g plate moving into them at 1 m/s: the
    /// plate and the particles end at one normal velocity, the plate slowed but not thrown back
    /// past them, and momentum is kept. (Each particle stopped against the plate's own motion
    /// would hand it 2.8 g m/s and throw it back at -1.15 m/s.)
    #[test]
    fn the_penalty_on_a_light_body_is_shared_not_stopped() {
        let (plate_kg, particle_kg) = (1.3e-3f32, 4.0e-4f32);
        let plate = ColliderMotion {
            linear_m_s: Vector3::new(1.0, 0.0, 0.0),
            angular_rad_s: Vector3::zeros(),
            centre_m: Vector3::zeros(),
            friction: 0.5,
            yield_inertia: Some(YieldInertia::free_body(plate_kg as f64, 1.0e-7)),
            load_kick_m_s: Vector3::zeros(),
            load_kick_rad_s: Vector3::zeros(),
        };
        let offsets_mm = [(0, 0), (4, 0), (-4, 0), (0, 4), (0, -4), (3, 3), (-3, -3)];
        let position: Vec<Vector3<f32>> = offsets_mm
            .iter()
            .map(|&(y, z)| Vector3::new(1.0, y as f32, z as f32) * 1.0e-3)
            .collect();
        let mut velocity = vec![Vector3::zeros(); position.len()];
        let mass = vec![particle_kg; position.len()];
        let contacts: Vec<PenaltyContact> = (0..position.len())
            .map(|particle| PenaltyContact {
                particle,
                collider: 0,
                normal: Vector3::x(),
            })
            .collect();
        let mut impulses = Vec::new();
        let particles = PenaltyParticles {
            position: &position,
            velocity: &mut velocity,
            mass: &mass,
        };
        settle_penalty(particles, &[plate], &contacts, &mut impulses);

        let j = impulses[0].linear_n_s;
        let sand_momentum: Vector3<f64> = velocity
            .iter()
            .map(|v| (v * particle_kg).cast::<f64>())
            .sum();
        assert!(
            (sand_momentum + j).norm() < 1e-9,
            "momentum kept: {sand_momentum} {j}"
        );
        let plate_after = 1.0 + j.x / plate_kg as f64;
        let shared = (plate_kg / (plate_kg + 7.0 * particle_kg)) as f64;
        for v in &velocity {
            assert!(
                (v.x as f64 - shared).abs() < 1e-3,
                "particle at {v}, shared {shared}"
            );
        }
        assert!(
            (plate_after - shared).abs() < 1e-3,
            "plate at {plate_after} m/s, particles at {shared}"
        );
    }
}
