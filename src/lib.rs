//! sandstep: granular terrain for legged robots.
//!
//! Modules depend one way: [`mpm`] (the sand solver: no rigid bodies, no ROS) and [`robot`]
//! (the hexapod in rapier: no sand, no ROS) are used by [`scene`] (YAML scenes, building and
//! running them); [`analysis`] measures runs, [`experiment`] sweeps leg curvature and gait
//! frequency over scenes, and [`bench`] prints throughput figures.

pub mod analysis;
pub mod bag;
pub mod bench;
pub mod bench_rft;
pub mod cli;
pub mod config_error;
pub mod coupling;
pub mod experiment;
pub mod files;
pub mod mpm;
pub mod msgs;
pub mod progress;
pub mod robot;
pub mod ros;
pub mod scene;
pub mod shard;
pub mod sweep;
pub mod terrain;
