//! Measurements of simulation results.

pub mod bag;
pub mod collapse;
pub mod plots;
