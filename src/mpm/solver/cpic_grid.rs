//! The solver's side of CPIC (`crate::mpm::cpic`): the colours of the grid blocks near
//! colliders for one substep, the particles' tags kept from substep to substep, and what the
//! CPIC transfers of P2G and G2P read.

use nalgebra::Vector3;
use rayon::prelude::*;

use super::{local_base, split_runs, Solver};
use crate::mpm::cpic::{update_tags, ColliderImpulse, ColliderMotion, ColourBlock, NodeColour};
use crate::mpm::grid::{ArenaSlot, ParticleBlock, ARENA_NODES};
use crate::mpm::kernel::Stencil;

/// CPIC colours of the grid blocks near colliders, for one substep.
#[derive(Clone, Debug, Default)]
pub(super) struct GridColours {
    /// Grid block slot -> index in `blocks`, or `NO_COLOUR`.
    of_block: Vec<u32>,
    pub(super) blocks: Vec<ColourBlock>,
}

const NO_COLOUR: u32 = u32::MAX;

impl GridColours {
    pub(super) fn clear(&mut self, grid_blocks: usize) {
        self.of_block.clear();
        self.of_block.resize(grid_blocks, NO_COLOUR);
        self.blocks.clear();
    }

    /// Gives grid block `slot` the colours `colour`.
    fn set(&mut self, slot: usize, colour: ColourBlock) {
        self.of_block[slot] = self.blocks.len() as u32;
        self.blocks.push(colour);
    }

    /// Colours of grid block `slot`, if coloured.
    pub(super) fn block(&self, slot: usize) -> Option<&ColourBlock> {
        match self.of_block.get(slot) {
            Some(&c) if c != NO_COLOUR => Some(&self.blocks[c as usize]),
            _ => None,
        }
    }

    /// Whether any grid block of `pb`'s arena has colours: a collider is near.
    pub(super) fn near(&self, pb: &ParticleBlock) -> bool {
        !self.blocks.is_empty()
            && pb
                .arena_blocks
                .iter()
                .any(|&b| self.of_block[b as usize] != NO_COLOUR)
    }

    /// The 6x6x6 colour arena of a particle block, or None if none of its nodes is coloured.
    pub(super) fn arena(
        &self,
        pb: &ParticleBlock,
        slots: &[ArenaSlot; ARENA_NODES],
    ) -> Option<Box<[NodeColour; ARENA_NODES]>> {
        if !self.near(pb) {
            return None;
        }
        let mut arena = Box::new([NodeColour::default(); ARENA_NODES]);
        for (a, slot) in slots.iter().enumerate() {
            let c = self.of_block[pb.arena_blocks[slot.block as usize] as usize];
            if c != NO_COLOUR {
                arena[a] = self.blocks[c as usize][slot.node as usize];
            }
        }
        Some(arena)
    }
}

/// What the CPIC transfers of one particle block read besides the particle.
pub(super) struct CpicTransfer<'a> {
    /// Colour arena of the block.
    pub colours: &'a [NodeColour],
    pub colliders: &'a [ColliderMotion],
    /// Grid spacing (m).
    pub dx: f32,
}

/// A particle as the CPIC transfers see it, at the start of the substep.
pub(super) struct CpicParticle {
    pub x: Vector3<f32>,
    pub v: Vector3<f32>,
    pub mass: f32,
    pub tags: u64,
}

/// `a + b`, collider by collider (the shorter one padded with zeros).
pub(super) fn add_impulses(
    mut a: Vec<ColliderImpulse>,
    b: &[ColliderImpulse],
) -> Vec<ColliderImpulse> {
    if a.len() < b.len() {
        a.resize(b.len(), ColliderImpulse::default());
    }
    for (a, b) in a.iter_mut().zip(b) {
        a.linear_n_s += b.linear_n_s;
        a.angular_n_m_s += b.angular_n_m_s;
        a.sand_mass_kg += b.sand_mass_kg;
        a.sand_first_moment += b.sand_first_moment;
        a.sand_inertia += b.sand_inertia;
    }
    a
}

impl Solver {
    /// Gives the CPIC colours of the active blocks: `colour(block)` returns the colours of the
    /// block at block coordinate `block` (its node `n` is grid node `4 block + local(n)`, see
    /// [`crate::mpm::grid::SparseGrid::node_position`]), or None if no collider is near. Runs in
    /// parallel.
    pub(super) fn colour_blocks(
        &mut self,
        colour: impl Fn([i32; 3]) -> Option<ColourBlock> + Sync,
    ) {
        let coloured: Vec<Option<ColourBlock>> =
            self.grid.coords.par_iter().map(|&c| colour(c)).collect();
        for (slot, c) in coloured.into_iter().enumerate() {
            if let Some(c) = c {
                self.colours.set(slot, c);
            }
        }
    }

    /// Keeps each particle's CPIC tags (see [`crate::mpm::cpic::update_tags`]); clears them away
    /// from colliders. Free when no collider is near and no particle is tagged.
    pub(super) fn update_particle_tags(&mut self) {
        if self.colours.blocks.is_empty() && !self.tagged {
            return;
        }
        let grid = &self.grid;
        let colours = &self.colours;
        let slots = &self.arena_slots;
        let positions = &self.particles.position;
        let blocks = &grid.particle_blocks;
        let runs = split_runs(&mut self.particles.cpic_tags, blocks);
        self.tagged = runs
            .into_par_iter()
            .zip(blocks.par_iter())
            .map(|(tags, pb)| {
                let Some(arena) = colours.arena(pb, slots) else {
                    tags.fill(0);
                    return false;
                };
                for (tag, x) in tags.iter_mut().zip(&positions[pb.start..pb.end]) {
                    let s = Stencil::new(grid.to_grid(x));
                    *tag = update_tags(*tag, &arena[..], &s, local_base(&s, pb));
                }
                tags.iter().any(|&t| t != 0)
            })
            .reduce(|| false, |a, b| a || b);
    }
}
