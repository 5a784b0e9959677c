//! Sleeping sand: particle blocks at rest, with no collider near, are left out of the substep
//! (no P2G, grid update or G2P for them) until something comes close (docs/physics.md,
//! "Sleeping sand").
//!
//! A block (the particles whose stencil base node lies in one 4x4x4 grid block) falls asleep
//! when all its particles have been slower than `speed_m_s` for `after_s` of simulated time,
//! no wake zone (a collider's box grown by `wake_margin_m`) touches it and no neighbouring
//! block moves. Its particles are set at rest and keep their deformation and stress. While it
//! sleeps, the grid nodes its particles would reach are held at rest: to the awake sand next
//! to it the sleeping sand is a rigid, sticky support, as settled sand is. It wakes when a wake
//! zone touches it, when one of its 26 neighbouring blocks moves (some particle at or above
//! `speed_m_s`), or when an awake particle enters it.

use nalgebra::Vector3;

use super::grid::{BlockLattice, ParticleBlock, SparseGrid, BLOCK_EDGE};

/// When particle blocks sleep (`sand.solver.sleep`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SleepSettings {
    /// A block is quiet while all its particles are slower than this (m/s); a neighbour at or
    /// above it wakes a sleeping block.
    pub speed_m_s: f32,
    /// Quiet time after which a block falls asleep (s).
    pub after_s: f32,
    /// Blocks within this distance (m) of a wake zone (a collider's box) stay or come awake.
    pub wake_margin_m: f32,
}

/// An axis-aligned box `[min, max]` (m) near which sand must be awake, e.g. a collider's.
pub type WakeZone = [Vector3<f32>; 2];

/// Sleep state of every block of the grid's table, indexed by block key.
#[derive(Clone, Debug)]
pub struct Sleep {
    pub settings: SleepSettings,
    /// Per block: simulated time its particles have all been slower than `speed_m_s` (s).
    quiet_s: Vec<f32>,
    /// Per block: asleep.
    asleep: Vec<bool>,
    /// Per block: some particle at or above `speed_m_s` in the last substep.
    moving: Vec<bool>,
    /// Keys set in `moving`, to clear them cheaply.
    moving_keys: Vec<u32>,
    /// Per sleeping block: its particles when it fell asleep (another count means a particle
    /// entered it, or was removed).
    sleeping_particles: Vec<u32>,
    /// Blocks asleep now.
    asleep_count: usize,
}

/// What [`Sleep::update`] changed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SleepChanges {
    pub woken: usize,
    pub fell_asleep: usize,
}

impl Sleep {
    /// Every block awake, none quiet, for a grid of `blocks` table entries.
    pub fn new(settings: SleepSettings, blocks: usize) -> Self {
        Sleep {
            settings,
            quiet_s: vec![0.0; blocks],
            asleep: vec![false; blocks],
            moving: vec![false; blocks],
            moving_keys: Vec::new(),
            sleeping_particles: vec![0; blocks],
            asleep_count: 0,
        }
    }

    /// Whether the block with key `key` is asleep.
    #[inline]
    pub fn is_asleep(&self, key: u32) -> bool {
        self.asleep[key as usize]
    }

    /// Blocks asleep now.
    pub fn asleep_blocks(&self) -> usize {
        self.asleep_count
    }

    /// After G2P: each awake block's fastest particle speed (m/s) over a substep of `dt` (s).
    pub fn record_speeds(
        &mut self,
        blocks: &[ParticleBlock],
        keys: &[u32],
        speeds: &[f32],
        dt: f32,
    ) {
        for &key in &self.moving_keys {
            self.moving[key as usize] = false;
        }
        self.moving_keys.clear();
        for (pb, &speed) in blocks.iter().zip(speeds) {
            let key = keys[pb.start];
            let k = key as usize;
            if speed < self.settings.speed_m_s {
                self.quiet_s[k] += dt;
            } else {
                self.quiet_s[k] = 0.0;
                self.moving[k] = true;
                self.moving_keys.push(key);
            }
        }
    }

    /// Before the grid is built, with the particles sorted by `keys`: wakes the sleeping blocks
    /// that an awake particle has entered, that a wake zone touches or that have a moving
    /// neighbour; then puts to sleep the awake blocks quiet for `after_s` with neither. The
    /// particles of a block falling asleep are given `rest` (their index range) to be set at
    /// rest.
    pub fn update(
        &mut self,
        grid: &SparseGrid,
        keys: &[u32],
        wake_zones: &[WakeZone],
        mut rest: impl FnMut(std::ops::Range<usize>),
    ) -> SleepChanges {
        let mut changes = SleepChanges::default();
        let near_zone = self.blocks_near(grid, wake_zones);
        let lattice = grid.lattice();
        let has_moving_neighbour =
            |key: u32| lattice.neighbour_keys(key).any(|n| self.moving[n as usize]);
        // Wake: sleeping blocks near a zone or a moving block, or entered by awake particles.
        let mut wake: Vec<u32> = near_zone
            .iter()
            .copied()
            .filter(|&k| self.asleep[k as usize])
            .collect();
        if self.asleep_count > 0 {
            for &moving in &self.moving_keys {
                wake.extend(
                    lattice
                        .neighbour_keys(moving)
                        .filter(|&n| self.asleep[n as usize]),
                );
            }
            wake.extend(runs(keys).filter_map(|r| {
                let k = keys[r.start] as usize;
                let entered = self.asleep[k] && self.sleeping_particles[k] as usize != r.len();
                entered.then_some(k as u32)
            }));
        }
        for key in wake {
            if std::mem::replace(&mut self.asleep[key as usize], false) {
                self.quiet_s[key as usize] = 0.0;
                self.asleep_count -= 1;
                changes.woken += 1;
            }
        }
        // Sleep: quiet awake runs away from zones (`near_zone` is sorted) and moving blocks.
        for run in runs(keys) {
            let key = keys[run.start];
            let k = key as usize;
            if self.asleep[k]
                || self.quiet_s[k] < self.settings.after_s
                || near_zone.binary_search(&key).is_ok()
                || has_moving_neighbour(key)
            {
                continue;
            }
            self.asleep[k] = true;
            self.sleeping_particles[k] = run.len() as u32;
            self.asleep_count += 1;
            changes.fell_asleep += 1;
            rest(run);
        }
        changes
    }

    /// Keys of the blocks whose particles lie within `wake_margin_m` of a wake zone, sorted.
    fn blocks_near(&self, grid: &SparseGrid, zones: &[WakeZone]) -> Vec<u32> {
        let margin = self.settings.wake_margin_m;
        let lattice = grid.lattice();
        let mut keys = Vec::new();
        for [min, max] in zones {
            // A block's particles have stencil base nodes 4b..4b+3, so they lie within
            // [4b + 0.5, 4b + 4.5) cells of the origin along each axis.
            let lo = grid.to_grid(&min.add_scalar(-margin));
            let hi = grid.to_grid(&max.add_scalar(margin));
            let first = [0, 1, 2].map(|a| ((lo[a] - 4.5) / BLOCK_EDGE as f32).ceil() as i32);
            let last = [0, 1, 2].map(|a| ((hi[a] - 0.5) / BLOCK_EDGE as f32).floor() as i32);
            for x in first[0]..=last[0] {
                for y in first[1]..=last[1] {
                    for z in first[2]..=last[2] {
                        keys.extend(lattice.key_of_block([x, y, z]));
                    }
                }
            }
        }
        keys.sort_unstable();
        keys.dedup();
        keys
    }

    /// Whether grid node `index` is reached by the particles of a sleeping block (which reach
    /// nodes 4b..4b+5 of block b along each axis), so that it is held at rest.
    #[inline]
    pub fn holds_node(&self, lattice: &BlockLattice, index: [i32; 3]) -> bool {
        let candidates = index.map(|n| {
            let b = n.div_euclid(BLOCK_EDGE);
            (b, (n.rem_euclid(BLOCK_EDGE) <= 1).then_some(b - 1))
        });
        let along = |a: usize| {
            let (b, before) = candidates[a];
            std::iter::once(b).chain(before)
        };
        along(0).any(|x| {
            along(1).any(|y| {
                along(2).any(|z| {
                    lattice
                        .key_of_block([x, y, z])
                        .is_some_and(|k| self.asleep[k as usize])
                })
            })
        })
    }

    /// Whether grid block `coord` may hold nodes reached by a sleeping block (itself or one of
    /// the 7 blocks before it): the cheap test before [`Self::holds_node`].
    #[inline]
    pub fn near_grid_block(&self, lattice: &BlockLattice, coord: [i32; 3]) -> bool {
        self.asleep_count > 0
            && (0..8).any(|o| {
                let c = [
                    coord[0] - (o >> 2 & 1),
                    coord[1] - (o >> 1 & 1),
                    coord[2] - (o & 1),
                ];
                lattice
                    .key_of_block(c)
                    .is_some_and(|k| self.asleep[k as usize])
            })
    }
}

/// The index ranges of equal consecutive keys.
fn runs(keys: &[u32]) -> impl Iterator<Item = std::ops::Range<usize>> + '_ {
    let mut start = 0;
    std::iter::from_fn(move || {
        if start >= keys.len() {
            return None;
        }
        let key = keys[start];
        let end = start + keys[start..].iter().take_while(|&&k| k == key).count();
        let run = start..end;
        start = end;
        Some(run)
    })
}
