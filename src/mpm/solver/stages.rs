//! The substep's stages by name, and the wall time spent in each (as rapier's
//! `counters.stages`): [`StageTimes::time`] runs one stage and adds its time.

use std::time::{Duration, Instant};

/// One stage of the substep, in the order a substep runs them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    /// Sorting particles by grid block (`sort.rs`).
    Sort,
    /// Sleeping sand: waking and putting blocks to sleep (`sleep.rs` of `mpm`).
    Sleep,
    /// Finding the active blocks and clearing their nodes.
    GridAlloc,
    /// CPIC: colouring the grid near colliders and updating particle tags (`cpic_grid.rs`).
    Cpic,
    /// Particle to grid: fused APIC momentum and stress (`p2g.rs`).
    P2g,
    /// Grid velocities, gravity, walls (`grid_update.rs`).
    GridUpdate,
    /// Grid to particle: velocity and its gradient, advection, push-back (`g2p.rs`).
    G2p,
    /// Deformation gradient, constitutive update and blow-up check (`particle_update.rs`).
    ParticleUpdate,
}

impl Stage {
    /// Every stage, in substep order.
    pub const ALL: [Stage; 8] = [
        Stage::Sort,
        Stage::Sleep,
        Stage::GridAlloc,
        Stage::Cpic,
        Stage::P2g,
        Stage::GridUpdate,
        Stage::G2p,
        Stage::ParticleUpdate,
    ];

    /// The stage's name in summaries and benchmarks (`stage_times_s` of `sandstep run --json`).
    pub fn name(self) -> &'static str {
        match self {
            Stage::Sort => "sort",
            Stage::Sleep => "sleep",
            Stage::GridAlloc => "grid_alloc",
            Stage::Cpic => "cpic",
            Stage::P2g => "p2g",
            Stage::GridUpdate => "grid_update",
            Stage::G2p => "g2p",
            Stage::ParticleUpdate => "particle_update",
        }
    }
}

/// Wall time spent in each stage of the substep so far.
#[derive(Clone, Copy, Debug, Default)]
pub struct StageTimes {
    by_stage: [Duration; Stage::ALL.len()],
}

impl StageTimes {
    /// Runs `work` as `stage` and adds its wall time to the stage's.
    pub fn time<T>(&mut self, stage: Stage, work: impl FnOnce() -> T) -> T {
        let start = Instant::now();
        let out = work();
        self.by_stage[stage as usize] += start.elapsed();
        out
    }

    /// Wall time spent in `stage` so far.
    pub fn of(&self, stage: Stage) -> Duration {
        self.by_stage[stage as usize]
    }

    /// `(name, time)` of every stage, in substep order.
    pub fn named(&self) -> [(&'static str, Duration); Stage::ALL.len()] {
        Stage::ALL.map(|stage| (stage.name(), self.of(stage)))
    }

    pub fn total(&self) -> Duration {
        self.by_stage.iter().sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stages_are_indexed_in_substep_order() {
        for (i, stage) in Stage::ALL.iter().enumerate() {
            assert_eq!(*stage as usize, i, "{}", stage.name());
        }
        let mut times = StageTimes::default();
        let out = times.time(Stage::G2p, || {
            std::thread::sleep(Duration::from_millis(2));
            7
        });
        assert_eq!(out, 7);
        assert!(times.of(Stage::G2p) >= Duration::from_millis(2));
        assert_eq!(times.of(Stage::P2g), Duration::ZERO);
        assert_eq!(times.total(), times.of(Stage::G2p));
        assert_eq!(times.named()[6].0, "g2p");
    }
}
