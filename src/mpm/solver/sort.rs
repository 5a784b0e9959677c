//! Sort: particles in the order of the grid block of their stencil base node, so that each
//! block's particles are one run of the particle arrays (Gao et al. 2018's particle blocks).

use rayon::prelude::*;

use super::Solver;

impl Solver {
    /// Keeps particles sorted by the block of their stencil base node (stable, so the order is
    /// a pure function of the state: runs are deterministic for any thread count).
    pub(super) fn sort_particles_by_block(&mut self) {
        let grid = &self.grid;
        let positions = &self.particles.position;
        // A sleeping particle has not moved since its key was taken: it keeps it. (`keys` is
        // cleared whenever particles come or go, and a block's sleep changes only after the sort.)
        match &self.sleep {
            Some(sleep) if self.keys.len() == positions.len() => self
                .keys
                .par_iter_mut()
                .zip(positions.par_iter())
                .filter(|(key, _)| !sleep.is_asleep(**key))
                .for_each(|(key, x)| *key = grid.block_key(x)),
            _ => {
                self.keys.clear();
                self.keys
                    .par_extend(positions.par_iter().map(|x| grid.block_key(x)));
            }
        }
        if self.keys.par_windows(2).all(|w| w[0] <= w[1]) {
            return;
        }
        self.order.clear();
        self.order.extend(0..self.particles.len() as u32);
        let keys = &self.keys;
        self.order.par_sort_by_key(|&i| keys[i as usize]);
        self.particles
            .reorder(&self.order, &mut self.reorder_scratch);
        self.sorted_keys.clear();
        self.sorted_keys
            .par_extend(self.order.par_iter().map(|&i| keys[i as usize]));
        std::mem::swap(&mut self.keys, &mut self.sorted_keys);
    }
}
