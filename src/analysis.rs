//! Measurements of simulation results.

pub mod collapse;
