//! Terrain models: what the robot walks on, beside the MPM sand of [`crate::mpm`] (coupled to
//! the robot by [`crate::coupling`]'s CPIC).
//!
//! - [`config`]: the `terrain:` section of a scene, which picks the model (`mpm` or `rft`).
//! - [`rft`]: resistive force theory (Li, Zhang and Goldman 2013), a flat granular surface whose
//!   resistance is local and rate independent, hundreds of times cheaper than MPM.
//! - [`plate`] and [`calibration`]: a plate pressed into MPM sand, and the fit of RFT's scale
//!   zeta to it (`sandstep calibrate-rft`).
//! - [`stress_law`]: RFT's stress law alpha(beta, gamma): the generic shape, fitted
//!   coefficients or a measured table, extended to every angle by RFT's symmetries.
//! - [`stress_map`]: RFT's stress per unit depth over attack and intrusion angle, measured on
//!   MPM sand with a leg-sized plate and fitted (`sandstep calibrate-rft --maps`).
//!
//! Rigid ground, the third model, is rapier's ground plane under the robot (`crate::robot`).

pub mod blade;
pub mod calibration;
pub mod config;
pub mod plate;
pub mod rft;
pub mod stress_law;
pub mod stress_map;

pub use config::{
    MapsLaw, RftCalibrationConfig, RftConfig, RftParams, RftStep, StressMapsChoice, TerrainConfig,
    TerrainModel, DEFAULT_ZETA_N_M3, POPPY_SEEDS_ZETA_N_M3,
};
