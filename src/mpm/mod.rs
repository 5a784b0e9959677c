//! The explicit 3D MLS-MPM sand solver (Hu et al. 2018), on a sparse block grid.
//!
//! Knows nothing of rigid bodies or ROS. One [`Solver::substep`] is sort, grid allocation,
//! P2G, grid update, G2P and the particle update (`docs/physics.md`, section 1;
//! `src/mpm/solver/`), each stage timed by name in [`StageTimes`].

pub mod boundary;
pub mod cpic;
pub mod grid;
pub mod kernel;
pub mod lattice;
pub mod material;
pub mod memory;
pub mod particles;
pub mod simd;
pub mod sleep;
pub mod solver;
pub mod svd;

pub use boundary::{Wall, Walls};
pub use particles::{NewParticle, Particles};
pub use sleep::SleepSettings;
pub use solver::{
    CpicBand, SimError, Solver, SolverMaterial, SolverSettings, Stage, StageTimes, TimeStep,
    Transfer, DEFAULT_CPIC_BAND_RELAXATION_S, DEFAULT_FLIP_RELAXATION_S,
};
