//! P2G: each particle's mass and momentum, with the MLS-MPM stress and APIC affine terms fused
//! (Hu et al. 2018, eq. 29), go to the 27 nodes of its stencil; near colliders, CPIC leaves out
//! the nodes across a collider and hands what they would have received to the collider. With
//! AFLIP the mass and momentum without the stress term go to a second grid as well.

use nalgebra::{Matrix3, Vector3};
use std::sync::atomic::Ordering;

use rayon::prelude::*;

use super::cpic_grid::{add_impulses, CpicParticle, CpicTransfer, GridColours};
use super::settings::KeptShares;
use super::{local_base, scale_columns, CpicBand, Solver, Transfer};
use crate::mpm::cpic::{
    conflict_normal, conflicts, stencil_nodes, ColliderImpulse, ColliderMotion, NodeColour,
};
use crate::mpm::grid::{
    node_in_arena, ArenaSlot, Block, ParticleBlock, SparseGrid, ARENA_NODES, BLOCK_NODES,
};
use crate::mpm::kernel::{Kernel, Stencil};
use crate::mpm::particles::Particles;
use crate::mpm::simd::{array3, Node, NodePair, WithNodes, F4};

impl Solver {
    /// P2G: each particle block scatters into a private 6x6x6 arena, and arenas are added to the
    /// grid in 8 phases by block parity, so no two writers ever share a node (no atomics, no
    /// locks). Returns the momentum the colliders took in place of the nodes across them.
    pub(super) fn particle_to_grid(
        &mut self,
        dt: f32,
        colliders: &[ColliderMotion],
    ) -> Vec<ColliderImpulse> {
        let dx = self.settings.dx;
        // AFLIP measures a particle's deviation against the grid velocity its transfer alone
        // gives, without this substep's stress impulse: scattered a second time, stress left
        // out. The particles there are those that keep a deviation, each weighted by the share
        // `b_p` of it that it keeps, so that the kept deviations sum to zero momentum:
        // sum_p b_p m_p sum_i w_ip v~_i = sum_i m~_i v~_i with m~_i = sum_p b_p m_p w_ip. With
        // `CpicBand::Pic` those near a collider keep none and stay out (counted, a box thrown
        // into sand lost a third of its momentum, tests/coupling.rs); with `CpicBand::Bulk`
        // they scatter onto their compatible nodes, as on the grid, and G2P measures their
        // deviation over the same nodes (`CompatibleTransfer::deviation` in `g2p.rs`).
        // (Unweighted, the band's shorter relaxation time drifted the thrown box's momentum by
        // 0.84 %.)
        let keep_transferred = self.settings.transfer == Transfer::Aflip;
        let shares = self.settings.kept_shares(dt);
        let band_as_bulk = self.settings.cpic_band == CpicBand::Bulk;
        if keep_transferred {
            self.transferred_velocity.clear();
            self.transferred_velocity
                .resize(self.grid.blocks.len(), [[0.0; 4]; BLOCK_NODES]);
        }
        let transferred_blocks =
            keep_transferred.then(|| SharedBlocks::new(&mut self.transferred_velocity));
        // Q_p = -dt V_p tau_p D^-1 + m_p C_p, applied to offsets measured in cells (D^-1 =
        // 4/dx^2 for the quadratic B-spline).
        let stress_scale = -dt / (dx * dx) * dx;
        let grid_blocks = SharedBlocks::new(&mut self.grid.blocks);
        let context = P2gContext {
            grid: &self.grid,
            particles: &self.particles,
            colours: &self.colours,
            colliders,
            slots: &self.arena_slots,
            grid_blocks: &grid_blocks,
            transferred_blocks: transferred_blocks.as_ref(),
            dx,
            stress_scale,
            shares,
            band_as_bulk,
            kernel: self.settings.kernel,
        };
        let instruction_set = self.instruction_set;
        let stop = &*self.stop;
        let mut impulses = Vec::new();
        for phase in 0..8 {
            // After a stop request the grid is left half-filled: the substep is abandoned.
            let phase_impulses: Vec<Vec<ColliderImpulse>> = self
                .grid
                .particle_blocks
                .par_iter()
                .filter(|pb| pb.phase() == phase && !stop.load(Ordering::Relaxed))
                .map(|pb| instruction_set.dispatch_nodes(P2gBlock { cx: &context, pb }))
                .filter(|i| !i.is_empty())
                .collect();
            for block in &phase_impulses {
                impulses = add_impulses(impulses, block);
            }
        }
        impulses
    }
}

/// What P2G reads besides the particle block, and the grids it adds to.
struct P2gContext<'a> {
    grid: &'a SparseGrid,
    particles: &'a Particles,
    colours: &'a GridColours,
    colliders: &'a [ColliderMotion],
    slots: &'a [ArenaSlot; ARENA_NODES],
    grid_blocks: &'a SharedBlocks,
    /// AFLIP's transferred grid, or none (APIC, PIC).
    transferred_blocks: Option<&'a SharedBlocks>,
    /// Grid spacing (m).
    dx: f32,
    /// `-dt / dx` (s/m): the stress term's factor for offsets in cells.
    stress_scale: f32,
    /// Shares of a particle's deviation kept this substep (AFLIP).
    shares: KeptShares,
    band_as_bulk: bool,
    kernel: Kernel,
}

/// What particle `p` scatters, before the weights.
struct ParticleTerms {
    /// Position (m).
    x: Vector3<f32>,
    /// Its stencil: weights and base node.
    s: Stencil,
    /// Mass (kg).
    m: f32,
    /// Momentum (kg m/s).
    momentum: Vector3<f32>,
    /// `m_p C_p dx` (kg m/s): the affine momentum per cell of offset.
    q_transfer: Matrix3<f32>,
    /// `Q_p` for offsets in cells (kg m/s): the stress impulse and `q_transfer`.
    q_cells: Matrix3<f32>,
}

impl P2gContext<'_> {
    #[inline(always)]
    fn particle(&self, p: usize) -> ParticleTerms {
        let particles = self.particles;
        let x = particles.position[p];
        let s = Stencil::of(self.kernel, self.grid.to_grid(&x));
        let m = particles.mass[p];
        let momentum = particles.velocity[p] * m;
        let q_transfer = particles.affine[p] * (m * self.dx);
        let q_cells = scale_columns(
            &particles.stress[p],
            &(s.inverse_moment * self.stress_scale * particles.volume[p]),
        ) + q_transfer;
        ParticleTerms {
            x,
            s,
            m,
            momentum,
            q_transfer,
            q_cells,
        }
    }

    /// Scatters particle `p` (its terms `t`), tagged near a collider, with CPIC into `arena`
    /// ([`scatter_cpic`]), and with `transferred` (AFLIP's `Q` without stress and the kept
    /// share, `CpicBand::Bulk`) into the transferred grid's halves too.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn scatter_band<A: CpicArena + ?Sized>(
        &self,
        p: usize,
        t: &ParticleTerms,
        colour: &[NodeColour],
        pb: &ParticleBlock,
        arena: &mut A,
        transferred: Option<(&Matrix3<f32>, f32)>,
        impulses: &mut Vec<ColliderImpulse>,
    ) {
        impulses.resize(self.colliders.len(), ColliderImpulse::default());
        let particle = CpicParticle {
            x: t.x,
            v: self.particles.velocity[p],
            mass: t.m,
            tags: self.particles.cpic_tags[p],
        };
        let cpic = CpicTransfer {
            colours: colour,
            colliders: self.colliders,
            dx: self.dx,
        };
        let base = local_base(&t.s, pb);
        scatter_cpic(
            arena,
            transferred,
            &cpic,
            &t.s,
            base,
            &particle,
            &t.q_cells,
            impulses,
        );
    }
}

/// P2G of one particle block, as the work of
/// [`crate::mpm::simd::InstructionSet::dispatch_nodes`]:
/// compiled with the instruction set's features (VEX encoding with AVX2; the same bits, as no
/// product is fused).
/// Only what is inlined gets them: the CPIC band's `scatter_cpic` (`#[inline(never)]`) stays
/// compiled for the baseline.
struct P2gBlock<'a> {
    cx: &'a P2gContext<'a>,
    pb: &'a ParticleBlock,
}

impl WithNodes for P2gBlock<'_> {
    type Output = Vec<ColliderImpulse>;
    #[inline(always)]
    fn run<P: NodePair>(self) -> Self::Output {
        let cx = self.cx;
        match cx.transferred_blocks {
            Some(transferred) => particle_to_grid_pairs::<P>(cx, self.pb, transferred),
            None => particle_to_grid_block(cx, self.pb),
        }
    }
}

/// P2G of a particle block with AFLIP: each particle away from colliders scatters to the grid
/// and to the transferred grid in one pass of node pairs ([`NodePair`]), with the same weights
/// and the same bits as two passes of [`F4`]; each in the CPIC band adds to the pairs' halves
/// ([`scatter_cpic`]). Returns the momentum the colliders took (empty where no particle is near
/// one).
#[inline(always)]
fn particle_to_grid_pairs<P: NodePair>(
    cx: &P2gContext,
    pb: &ParticleBlock,
    transferred_blocks: &SharedBlocks,
) -> Vec<ColliderImpulse> {
    let P2gContext {
        particles,
        colours,
        slots,
        grid_blocks,
        shares,
        band_as_bulk,
        ..
    } = *cx;
    let mut arena = [P::splat(0.0); ARENA_NODES];
    let colour_arena = colours.arena(pb, slots);
    let mut block_impulses = Vec::new();
    let b = shares.bulk;
    for p in pb.start..pb.end {
        let t = cx.particle(p);
        let tags = particles.cpic_tags[p];
        if let Some(colour) = colour_arena.as_ref().filter(|_| tags != 0) {
            let transferred = band_as_bulk.then_some((&t.q_transfer, shares.band));
            let arena = P::halves_of(&mut arena);
            cx.scatter_band(
                p,
                &t,
                &colour[..],
                pb,
                arena,
                transferred,
                &mut block_impulses,
            );
            continue;
        }
        let grid_terms = NodeTerms::of(&t.s, t.m, t.momentum, &t.q_cells);
        let transferred_terms = NodeTerms::of(&t.s, t.m * b, t.momentum * b, &(t.q_transfer * b));
        let terms = NodeTerms {
            at_base: P::from_halves(grid_terms.at_base, transferred_terms.at_base),
            columns: array3!(c => P::from_halves(grid_terms.columns[c], transferred_terms.columns[c])),
        };
        scatter(&mut arena, &t.s, local_base(&t.s, pb), &terms);
    }
    let (mut low, mut high) = ([F4::splat(0.0); ARENA_NODES], [F4::splat(0.0); ARENA_NODES]);
    for (a, pair) in arena.iter().enumerate() {
        (low[a], high[a]) = (pair.low(), pair.high());
    }
    // SAFETY: as in `particle_to_grid_block`; the transferred velocities are laid out like
    // the grid's blocks.
    unsafe {
        grid_blocks.add_arena(&low, pb, slots);
        transferred_blocks.add_arena(&high, pb, slots);
    }
    block_impulses
}

/// P2G of one particle block into its private 6x6x6 arena, then added to the grid's blocks it
/// covers, without AFLIP (APIC, PIC; AFLIP's is [`particle_to_grid_pairs`]). Returns the
/// momentum the colliders took (empty where no particle is near one).
#[inline(always)]
fn particle_to_grid_block(cx: &P2gContext, pb: &ParticleBlock) -> Vec<ColliderImpulse> {
    let P2gContext {
        particles,
        colours,
        slots,
        grid_blocks,
        ..
    } = *cx;
    let mut arena = [F4::splat(0.0); ARENA_NODES];
    let colour_arena = colours.arena(pb, slots);
    let mut block_impulses = Vec::new();
    for p in pb.start..pb.end {
        let t = cx.particle(p);
        match &colour_arena {
            Some(colour) if particles.cpic_tags[p] != 0 => {
                cx.scatter_band(
                    p,
                    &t,
                    &colour[..],
                    pb,
                    &mut arena,
                    None,
                    &mut block_impulses,
                );
            }
            _ => {
                let terms = NodeTerms::of(&t.s, t.m, t.momentum, &t.q_cells);
                scatter(&mut arena, &t.s, local_base(&t.s, pb), &terms);
            }
        }
    }
    // SAFETY: blocks of one phase have disjoint arenas (see
    // `ParticleBlock::phase`), so these blocks are written by no other task.
    unsafe { grid_blocks.add_arena(&arena, pb, slots) };
    block_impulses
}

/// One particle's mass and momentum as [`scatter`] spreads them: at the stencil's first node,
/// and the change per node along each axis.
struct NodeTerms<N> {
    /// `[m_p v_p - Q_p fx, m_p]`: what the node at offset zero gets before its weight.
    at_base: N,
    /// The columns of `Q_p` (cells) with a zero mass lane: what one node further along each
    /// axis adds.
    columns: [N; 3],
}

impl NodeTerms<F4> {
    /// For mass `mass` (kg), momentum `momentum` (kg m/s) and `q_cells`, Q_p scaled for
    /// offsets in cells.
    #[inline(always)]
    fn of(s: &Stencil, mass: f32, momentum: Vector3<f32>, q_cells: &Matrix3<f32>) -> Self {
        let p = momentum - q_cells * s.fx;
        NodeTerms {
            at_base: F4::from_array([p.x, p.y, p.z, mass]),
            columns: array3!(c => F4::from_array([q_cells[(0, c)], q_cells[(1, c)], q_cells[(2, c)], 0.0])),
        }
    }
}

/// Adds one particle's mass and momentum `w_ip (m_p v_p + Q_p (x_i - x_p))` to its 27 arena
/// nodes. With `x_i - x_p = (i, j, k) - fx` (cells) the affine term is built up one axis at a
/// time, and a node's four components `[p_x, p_y, p_z, m]` are one SIMD vector (or, for node
/// pairs, eight): two multiplies and two adds per node.
#[inline(always)]
fn scatter<N: Node>(
    arena: &mut [N; ARENA_NODES],
    s: &Stencil,
    base: [usize; 3],
    terms: &NodeTerms<N>,
) {
    let q = terms.columns;
    let w_k = array3!(k => N::splat(s.weights[2][k]));
    let mut p_i = terms.at_base;
    for i in 0..3 {
        let mut p_ij = p_i;
        for j in 0..3 {
            let w_ij = N::splat(s.weights[0][i] * s.weights[1][j]);
            let row = node_in_arena(base[0] + i, base[1] + j, base[2]);
            let p_ij0 = p_ij * w_ij;
            let q_k = q[2] * w_ij;
            arena[row] = arena[row] + p_ij0 * w_k[0];
            arena[row + 1] = arena[row + 1] + (p_ij0 + q_k) * w_k[1];
            arena[row + 2] = arena[row + 2] + (p_ij0 + q_k + q_k) * w_k[2];
            p_ij = p_ij + q[1];
        }
        p_i = p_i + q[0];
    }
}

/// The arena [`scatter_cpic`] adds to: the grid's alone ([`F4`] nodes), or node pairs as
/// halves, `[grid's, transferred grid's]` ([`NodePair::halves_of`]).
trait CpicArena {
    /// Adds `grid` to the grid's node `a`, and `transferred` to the transferred grid's.
    fn add(&mut self, a: usize, grid: F4, transferred: Option<F4>);
}

impl CpicArena for [F4; ARENA_NODES] {
    #[inline(always)]
    fn add(&mut self, a: usize, grid: F4, _: Option<F4>) {
        self[a] = self[a] + grid;
    }
}

impl CpicArena for [[F4; 2]; ARENA_NODES] {
    #[inline(always)]
    fn add(&mut self, a: usize, grid: F4, transferred: Option<F4>) {
        let [grid_node, transferred_node] = &mut self[a];
        *grid_node = *grid_node + grid;
        if let Some(t) = transferred {
            *transferred_node = *transferred_node + t;
        }
    }
}

/// [`scatter`] with CPIC: a node incompatible with the particle receives nothing; the collider
/// of the conflict receives, at the node, the momentum the particle would have left there less
/// what the ghost velocity gives back in G2P. With AFLIP, `transferred` is the particle's `Q`
/// without stress and the share of its deviation it keeps: its compatible nodes receive in
/// the transferred grid's half of `arena` too, weighted by the share.
#[allow(clippy::too_many_arguments)]
#[inline(never)]
fn scatter_cpic<A: CpicArena + ?Sized>(
    arena: &mut A,
    transferred: Option<(&Matrix3<f32>, f32)>,
    cx: &CpicTransfer,
    s: &Stencil,
    base: [usize; 3],
    p: &CpicParticle,
    q_cells: &Matrix3<f32>,
    impulses: &mut [ColliderImpulse],
) {
    let momentum = p.v * p.mass;
    for (a, w, d) in stencil_nodes(s, base) {
        let contribution = (momentum + q_cells * d) * w;
        let colour = &cx.colours[a];
        let conflict = conflicts(colour.bits, p.tags);
        if conflict == 0 {
            let node = F4::from_array([contribution.x, contribution.y, contribution.z, w * p.mass]);
            let transferred_node = transferred.map(|(q_transfer, share)| {
                let weight = w * share;
                let c = (momentum + q_transfer * d) * weight;
                F4::from_array([c.x, c.y, c.z, weight * p.mass])
            });
            arena.add(a, node, transferred_node);
        } else {
            // The collider takes what the node would have received; G2P subtracts what the
            // ghost velocity gives back.
            let x_node = p.x + d * cx.dx;
            let (r, _) = conflict_normal(colour, conflict, p.tags);
            let centre = &cx.colliders[r].centre_m;
            impulses[r].add_sand(w * p.mass, contribution, &x_node, centre);
        }
    }
}

/// Grid blocks written from parallel P2G tasks that are known to touch disjoint blocks.
struct SharedBlocks {
    ptr: *mut Block,
    len: usize,
}

// SAFETY: access goes through `get_mut`, whose callers guarantee disjointness.
unsafe impl Sync for SharedBlocks {}
unsafe impl Send for SharedBlocks {}

impl SharedBlocks {
    fn new(blocks: &mut [Block]) -> Self {
        SharedBlocks {
            ptr: blocks.as_mut_ptr(),
            len: blocks.len(),
        }
    }

    /// Adds the 6x6x6 `arena` of particle block `pb` to the blocks it covers.
    ///
    /// # Safety
    /// No other task may touch those blocks meanwhile.
    unsafe fn add_arena(
        &self,
        arena: &[F4; ARENA_NODES],
        pb: &ParticleBlock,
        slots: &[ArenaSlot; ARENA_NODES],
    ) {
        for (a, slot) in slots.iter().enumerate() {
            let block = self.get_mut(pb.arena_blocks[slot.block as usize]);
            let node = &mut block[slot.node as usize];
            *node = (F4::from_array(*node) + arena[a]).to_array();
        }
    }

    /// # Safety
    /// No other reference to block `i` may exist while the returned one lives.
    #[allow(clippy::mut_from_ref)]
    unsafe fn get_mut(&self, i: u32) -> &mut Block {
        assert!((i as usize) < self.len);
        &mut *self.ptr.add(i as usize)
    }
}
