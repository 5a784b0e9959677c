//! The hexapod of Hu et al. 2018 (after Li, Zhang and Goldman 2013): URDF generation,
//! loading into rapier as a multibody, and the alternating tripod gait on rigid ground.
//!
//! - [`geometry`]: legs (arcs of signed curvature), body, hips, mass properties.
//! - [`urdf_gen`]: the URDF and leg mesh behind `sandstep urdf` (`urdf/*.urdf`, `urdf/meshes/*.stl`).
//! - [`loader`]: URDF checks with errors naming file and element.
//! - [`gait`]: tripod phases and the torque-limited DC motor (pure, no rapier).
//! - [`sim`]: [`RobotSim`], the rapier world.
//!
//! Depends on rapier and nothing of the sand solver. Units SI, frame REP-103 (x forward,
//! y left, z up). See docs/robot.md.

pub mod config;
pub mod error;
pub mod gait;
pub mod geometry;
pub mod loader;
pub mod mesh;
pub mod sim;
pub mod urdf_gen;

pub use config::{GaitConfig, GroundConfig, InitialPose, MotorConfig, PhysicsConfig, RobotConfig};
pub use error::RobotError;
pub use gait::GaitCommand;
pub use geometry::{HexapodParams, LegParams, LEGS, LEG_COUNT};
pub use sim::{RobotMetrics, RobotSim, RobotState};
pub use urdf_gen::{leg_mesh_path, write_hexapod_urdf};
