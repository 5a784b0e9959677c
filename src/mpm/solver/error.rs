//! Why a substep cannot go on.

/// A simulation that cannot go on.
#[derive(thiserror::Error, Debug, Clone)]
pub enum SimError {
    #[error(
        "simulation blew up at step {step} (t = {time_s:.6} s, dt = {dt_s:.3e} s): particle {particle} {what} \
         (position {position:?} m, velocity {velocity:?} m/s); reduce the time step (solver.cfl, \
         solver.max_dt_s, solver.fixed_dt_s) or check the material parameters"
    )]
    BlowUp {
        step: u64,
        time_s: f64,
        dt_s: f32,
        /// Persistent id of the worst particle.
        particle: u32,
        what: String,
        position: [f32; 3],
        velocity: [f32; 3],
    },
    /// A stop request ([`super::Solver::stop_on`]) seen inside a substep, before any particle
    /// had moved: the sand is as it was at `time_s`.
    #[error(
        "stopped in substep {step} (t = {time_s:.6} s), during {stage}, before any particle moved"
    )]
    Stopped {
        step: u64,
        time_s: f64,
        stage: &'static str,
    },
    /// A stop request seen during G2P: `moved` of `blocks` particle blocks had already moved on
    /// by `dt_s` (each particle is whole, at `time_s` or `time_s + dt_s`), so the sand cannot be
    /// stepped further.
    #[error(
        "stopped in substep {step} (t = {time_s:.6} s), during g2p: {moved} of {blocks} particle \
         blocks had moved on by dt = {dt_s:.3e} s; the sand cannot be stepped further"
    )]
    StoppedMidTransfer {
        step: u64,
        time_s: f64,
        dt_s: f32,
        moved: usize,
        blocks: usize,
    },
}

impl SimError {
    /// Whether this is a stop request rather than a failure.
    pub fn is_stop(&self) -> bool {
        matches!(
            self,
            SimError::Stopped { .. } | SimError::StoppedMidTransfer { .. }
        )
    }
}
