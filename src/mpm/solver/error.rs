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
}
