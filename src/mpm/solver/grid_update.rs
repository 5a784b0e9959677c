//! Grid update: node momentum to velocity, gravity, the walls, the velocity imposed by the
//! plain grid-boundary method near colliders, and sleeping sand holding its nodes at rest.

use nalgebra::Vector3;
use rayon::prelude::*;

use super::{Solver, Transfer};
use crate::mpm::cpic::ColliderMotion;
use crate::mpm::grid::BLOCK_EDGE;

impl Solver {
    /// Grid update: velocity from momentum, gravity, then the walls (and, for nodes coloured
    /// for the plain grid-boundary method, the imposed collider velocity).
    pub(super) fn update_grid(&mut self, dt: f32, colliders: &[ColliderMotion]) {
        if self.settings.transfer == Transfer::Aflip {
            self.transferred_momentum_to_velocity();
        }
        let gravity = self.settings.gravity * dt;
        let walls = self.settings.walls;
        let wall_nodes = self.wall_nodes;
        let coords = &self.grid.coords;
        let colours = &self.colours;
        let (origin, dx) = (self.grid.origin, self.grid.dx);
        let (sleep, lattice) = (self.sleep.as_ref(), self.grid.lattice());
        self.grid
            .blocks
            .par_iter_mut()
            .zip(coords.par_iter())
            .enumerate()
            .for_each(|(slot, (block, coord))| {
                let first = coord.map(|c| c * BLOCK_EDGE);
                let near_wall = (0..3).any(|a| {
                    first[a] <= wall_nodes[0][a] || first[a] + BLOCK_EDGE > wall_nodes[1][a]
                });
                let colour = colours.block(slot);
                let near_sleep = sleep.filter(|s| s.near_grid_block(&lattice, *coord));
                for (n, node) in block.iter_mut().enumerate() {
                    let mass = node[3];
                    if mass <= 0.0 {
                        continue;
                    }
                    let mut v = Vector3::new(node[0], node[1], node[2]) / mass + gravity;
                    let index = || {
                        let local = [n / 16, (n / 4) % 4, n % 4];
                        [0, 1, 2].map(|a| first[a] + local[a] as i32)
                    };
                    if near_wall {
                        v = walls.apply_at_node(v, index(), &wall_nodes);
                    }
                    if let Some(imposed) = colour.map(|c| c[n].imposed).filter(|&i| i != 0) {
                        let x = origin + Vector3::from(index().map(|i| i as f32)) * dx;
                        v = colliders[imposed as usize - 1].velocity_at(&x);
                    }
                    // Sleeping sand holds the nodes it reaches at rest.
                    if near_sleep.is_some_and(|s| s.holds_node(&lattice, index())) {
                        v = Vector3::zeros();
                    }
                    node[0] = v.x;
                    node[1] = v.y;
                    node[2] = v.z;
                }
            });
    }

    /// AFLIP: turns the momentum P2G's transfer alone left at each node into the node's
    /// velocity `p_i / m_i` (zero where no mass), for G2P's deviation.
    fn transferred_momentum_to_velocity(&mut self) {
        self.transferred_velocity.par_iter_mut().for_each(|block| {
            for node in block.iter_mut() {
                let mass = node[3];
                *node = if mass > 0.0 {
                    let v = Vector3::new(node[0], node[1], node[2]) / mass;
                    [v.x, v.y, v.z, mass]
                } else {
                    [0.0; 4]
                };
            }
        });
    }
}
