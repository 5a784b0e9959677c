//! Why a run stops: the errors of building and stepping a [`super::Simulation`] and of the run
//! loop around it ([`super::run`]).

use std::path::PathBuf;

use crate::coupling::CouplingError;
use crate::mpm::SimError;
use crate::robot::RobotError;
use crate::terrain::rft::RftError;

/// What an observer of a run ([`super::Observer`]: a bag recorder, a publisher) reports when it
/// cannot go on; it keeps its own error type inside.
pub type ObserverError = Box<dyn std::error::Error + Send + Sync>;

/// A run that cannot be built or cannot go on.
#[derive(thiserror::Error, Debug)]
pub enum RunError {
    #[error(transparent)]
    Sim(#[from] SimError),
    #[error("cannot write {}: {source}", path.display())]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error(transparent)]
    Robot(#[from] RobotError),
    /// The sand would not fit in memory (`super::memory`).
    #[error("{0}")]
    Memory(String),
    /// A stop request (Ctrl-C, SIGTERM) arrived while the scene was being built.
    #[error("stopped while {0}, before the first substep: nothing was simulated")]
    StoppedLoading(&'static str),
    #[error("scene {0} has nothing to simulate (no `sand` or `robot` section)")]
    Empty(String),
    #[error(transparent)]
    Coupling(#[from] CouplingError),
    #[error(transparent)]
    Rft(#[from] RftError),
    #[error(
        "the robot blew up at t = {time_s:.6} s: body at {position_m:?} m moving at {speed_m_s:.3e} m/s; \
         reduce robot.physics.max_dt_s or check the URDF's masses and inertias"
    )]
    RobotBlowUp {
        time_s: f64,
        position_m: [f32; 3],
        speed_m_s: f64,
    },
    /// `error` is the observer's own (not `source`, so that a report with causes does not
    /// print it twice).
    #[error("recording at t = {time_s:.6} s: {error}")]
    Observer { time_s: f64, error: ObserverError },
}
