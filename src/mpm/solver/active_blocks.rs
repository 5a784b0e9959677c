//! Which blocks take part in the substep: sleeping sand wakes or falls asleep, and the grid is
//! allocated over the awake particles' blocks.

use nalgebra::{Matrix3, Vector3};

use super::Solver;
use crate::mpm::sleep::WakeZone;

impl Solver {
    /// Wakes and puts to sleep blocks of sand (with `settings.sleep`; sand near `wake_zones`
    /// stays awake). Particles falling asleep lose their velocity and affine matrix.
    pub(super) fn update_sleep(&mut self, wake_zones: &[WakeZone]) {
        let Some(sleep) = &mut self.sleep else {
            return;
        };
        let (velocity, affine) = (&mut self.particles.velocity, &mut self.particles.affine);
        let changes = sleep.update(&self.grid, &self.keys, wake_zones, |run| {
            velocity[run.clone()].fill(Vector3::zeros());
            affine[run].fill(Matrix3::zeros());
        });
        self.sleep_changes.woken += changes.woken;
        self.sleep_changes.fell_asleep += changes.fell_asleep;
    }

    /// Rebuilds the sparse grid over the blocks of the awake particles, nodes cleared, and
    /// clears the CPIC colours.
    pub(super) fn allocate_grid(&mut self) {
        let sleep = &self.sleep;
        self.grid.rebuild(&self.keys, |key| {
            sleep.as_ref().is_some_and(|s| s.is_asleep(key))
        });
        self.colours.clear(self.grid.blocks.len());
    }
}
