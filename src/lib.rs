//! sandstep: granular terrain for legged robots.
//!
//! Modules depend one way: [`mpm`] (the sand solver, no rigid bodies, no ROS) is used by
//! [`scene`] (YAML scenes, building and running them) and [`analysis`] (metrics of runs).

pub mod analysis;
pub mod mpm;
pub mod scene;
