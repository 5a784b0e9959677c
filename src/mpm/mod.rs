//! The explicit 3D MLS-MPM sand solver (Hu et al. 2018), on a sparse block grid.
//!
//! Knows nothing of rigid bodies or ROS. One [`Solver::substep`] is P2G, grid update, G2P
//! (see `docs/physics.md`, section 1), each stage timed by name in [`StageTimes`].

pub mod material;
pub mod svd;
