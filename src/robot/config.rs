//! The `robot:` section of a scene YAML. Every field has a unit in its name and a default.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::error::RobotError;

/// Everything under the `robot:` key of a scene YAML.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotConfig {
    /// URDF of the robot, relative to the current working directory like every path of a
    /// scene (run from the repository root). Default `urdf/hexapod.urdf`.
    #[serde(default = "default_urdf")]
    pub urdf: PathBuf,
    /// Where the robot starts.
    #[serde(default)]
    pub initial_pose: InitialPose,
    /// Gait and motors.
    #[serde(default)]
    pub gait: GaitConfig,
    /// The flat rigid ground (the plane z = 0).
    #[serde(default)]
    pub ground: GroundConfig,
    /// Rigid-body integration (rapier).
    #[serde(default)]
    pub physics: PhysicsConfig,
}

/// Starting pose of the body. Its height is not given: the robot is placed so that its
/// lowest collision shape is `clearance_m` above the ground, legs at gait phase 0 (tripod A
/// pointing straight down, tripod B straight up).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InitialPose {
    /// Body centre x, y (m). Default [0, 0].
    #[serde(default)]
    pub position_m: [f64; 2],
    /// Heading: rotation about +z from the x axis (deg). Default 0 (facing +x).
    #[serde(default)]
    pub yaw_deg: f64,
    /// Gap between the lowest collision shape and the ground at t = 0 (m). Default 0.001.
    #[serde(default = "default_clearance_m")]
    pub clearance_m: f64,
}

/// Alternating tripod gait (see docs/robot.md).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GaitConfig {
    /// Leg rotation frequency (Hz); negative walks backward. Default 4.0 (the MLS-MPM
    /// reference scene turns the legs at 25 rad/s = 3.98 Hz).
    #[serde(default = "default_frequency_hz")]
    pub frequency_hz: f64,
    /// Right-side minus left-side frequency (Hz): the left legs turn at `frequency_hz - d/2`,
    /// the right legs at `frequency_hz + d/2`. Positive turns a forward-walking robot left
    /// (counter-clockwise seen from above). Default 0.
    #[serde(default)]
    pub turn_frequency_difference_hz: f64,
    /// The leg motors.
    #[serde(default)]
    pub motor: MotorConfig,
}

/// One torque-limited DC motor per leg, tracking the gait phase with a PD law. Available
/// torque falls linearly from the stall torque at rest to zero at the no-load speed while
/// driving; braking is limited to the stall torque.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MotorConfig {
    /// Torque at zero speed (N m, per leg). Default 0.1.
    #[serde(default = "default_stall_torque_n_m")]
    pub stall_torque_n_m: f64,
    /// Speed at which the driving torque reaches zero (rad/s). Default 50.
    #[serde(default = "default_no_load_speed_rad_s")]
    pub no_load_speed_rad_s: f64,
    /// Torque per radian of phase error (N m/rad). Default 1.0: stall torque at 5.7 deg.
    #[serde(default = "default_position_gain")]
    pub position_gain_n_m_per_rad: f64,
    /// Torque per rad/s of speed error (N m s/rad). Default 0.002, the slope
    /// stall torque / no-load speed of the DC motor's torque-speed line.
    #[serde(default = "default_velocity_gain")]
    pub velocity_gain_n_m_s_per_rad: f64,
}

/// The rigid ground.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GroundConfig {
    /// Coulomb friction coefficient between robot and ground (-). Set on both the ground's
    /// and the robot's colliders, so the contact uses exactly this value. Default 0.5.
    #[serde(default = "default_friction")]
    pub friction: f64,
    /// Height of the rigid ground plane (m). Default 0. The robot always starts just above
    /// z = 0; on sand whose surface is at z = 0 this is the floor under the bed.
    #[serde(default)]
    pub height_m: f64,
}

/// Rigid-body integration settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PhysicsConfig {
    /// Largest rapier time step (s): on rigid ground a frame is split into `ceil(frame /
    /// max_dt_s)` equal steps; on MPM sand it bounds the shared sand and rapier step. Not used
    /// on RFT ground (`terrain.rft.max_dt_s`). Default 0.001.
    #[serde(default = "default_max_dt_s")]
    pub max_dt_s: f64,
    /// Rapier solver iterations (substeps of its soft-constraint solver) per step. Default 4.
    #[serde(default = "default_solver_iterations")]
    pub solver_iterations: usize,
    /// Rapier's length unit (m): contact tolerances scale with it, and the robot is
    /// centimetre-sized. Default 0.01.
    #[serde(default = "default_length_unit_m")]
    pub length_unit_m: f64,
}

fn default_urdf() -> PathBuf {
    PathBuf::from("urdf/hexapod.urdf")
}
fn default_clearance_m() -> f64 {
    0.001
}
fn default_frequency_hz() -> f64 {
    4.0
}
fn default_stall_torque_n_m() -> f64 {
    0.1
}
fn default_no_load_speed_rad_s() -> f64 {
    50.0
}
fn default_position_gain() -> f64 {
    1.0
}
fn default_velocity_gain() -> f64 {
    0.002
}
fn default_friction() -> f64 {
    0.5
}
fn default_max_dt_s() -> f64 {
    0.001
}
fn default_solver_iterations() -> usize {
    4
}
fn default_length_unit_m() -> f64 {
    0.01
}

impl Default for RobotConfig {
    fn default() -> Self {
        Self {
            urdf: default_urdf(),
            initial_pose: InitialPose::default(),
            gait: GaitConfig::default(),
            ground: GroundConfig::default(),
            physics: PhysicsConfig::default(),
        }
    }
}

impl Default for InitialPose {
    fn default() -> Self {
        Self {
            position_m: [0.0; 2],
            yaw_deg: 0.0,
            clearance_m: default_clearance_m(),
        }
    }
}

impl Default for GaitConfig {
    fn default() -> Self {
        Self {
            frequency_hz: default_frequency_hz(),
            turn_frequency_difference_hz: 0.0,
            motor: MotorConfig::default(),
        }
    }
}

impl Default for MotorConfig {
    fn default() -> Self {
        Self {
            stall_torque_n_m: default_stall_torque_n_m(),
            no_load_speed_rad_s: default_no_load_speed_rad_s(),
            position_gain_n_m_per_rad: default_position_gain(),
            velocity_gain_n_m_s_per_rad: default_velocity_gain(),
        }
    }
}

impl Default for GroundConfig {
    fn default() -> Self {
        Self {
            friction: default_friction(),
            height_m: 0.0,
        }
    }
}

impl Default for PhysicsConfig {
    fn default() -> Self {
        Self {
            max_dt_s: default_max_dt_s(),
            solver_iterations: default_solver_iterations(),
            length_unit_m: default_length_unit_m(),
        }
    }
}

/// Largest accepted rapier step (s): the 2 g legs turning at tens of rad/s need milliseconds.
const MAX_PHYSICS_DT_S: f64 = 0.01;
/// Largest accepted number of solver iterations.
const MAX_SOLVER_ITERATIONS: usize = 100;
/// Largest start yaw accepted (deg): one turn either way.
const MAX_YAW_DEG: f64 = 360.0;
/// Largest accepted initial clearance (m): higher drops would land the robot hard.
const MAX_CLEARANCE_M: f64 = 0.1;

impl RobotConfig {
    /// Checks every value; the error names `yaml_path` and the field (`robot.gait...`).
    pub fn validate(&self, yaml_path: &Path) -> Result<(), RobotError> {
        let fail = |field: &str, value: String, reason: &str| RobotError::Config {
            file: yaml_path.to_path_buf(),
            field: format!("robot.{field}"),
            value,
            reason: reason.to_string(),
        };
        let finite = |field: &str, v: f64| {
            if v.is_finite() {
                Ok(())
            } else {
                Err(fail(field, v.to_string(), "must be a finite number"))
            }
        };
        let positive = |field: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(fail(field, v.to_string(), "must be a positive number"))
            }
        };
        let non_negative = |field: &str, v: f64| {
            if v.is_finite() && v >= 0.0 {
                Ok(())
            } else {
                Err(fail(field, v.to_string(), "must be zero or positive"))
            }
        };

        if self.urdf.as_os_str().is_empty() {
            return Err(fail("urdf", "\"\"".into(), "must name a URDF file"));
        }
        if self.urdf.is_dir() {
            return Err(fail(
                "urdf",
                self.urdf.display().to_string(),
                "is a directory; name a URDF file in it (e.g. urdf/hexapod.urdf)",
            ));
        }
        if !self.urdf.is_file() {
            return Err(fail(
                "urdf",
                self.urdf.display().to_string(),
                "file not found (paths are relative to the working directory; \
                 `sandstep urdf` writes urdf/hexapod.urdf)",
            ));
        }
        let pose = &self.initial_pose;
        finite("initial_pose.position_m[0]", pose.position_m[0])?;
        finite("initial_pose.position_m[1]", pose.position_m[1])?;
        finite("initial_pose.yaw_deg", pose.yaw_deg)?;
        if pose.yaw_deg.abs() > MAX_YAW_DEG {
            // Beyond a turn the angle says nothing more, and huge values overflow the f32
            // rotation (NaN pose; found by tests/fuzz.rs with 1e308).
            return Err(fail(
                "initial_pose.yaw_deg",
                pose.yaw_deg.to_string(),
                &format!("must be within +-{MAX_YAW_DEG} deg"),
            ));
        }
        non_negative("initial_pose.clearance_m", pose.clearance_m)?;
        if pose.clearance_m > MAX_CLEARANCE_M {
            return Err(fail(
                "initial_pose.clearance_m",
                pose.clearance_m.to_string(),
                &format!("must be at most {MAX_CLEARANCE_M} m"),
            ));
        }

        let motor = &self.gait.motor;
        positive("gait.motor.stall_torque_n_m", motor.stall_torque_n_m)?;
        positive("gait.motor.no_load_speed_rad_s", motor.no_load_speed_rad_s)?;
        positive(
            "gait.motor.position_gain_n_m_per_rad",
            motor.position_gain_n_m_per_rad,
        )?;
        non_negative(
            "gait.motor.velocity_gain_n_m_s_per_rad",
            motor.velocity_gain_n_m_s_per_rad,
        )?;
        let gait = &self.gait;
        finite("gait.frequency_hz", gait.frequency_hz)?;
        finite(
            "gait.turn_frequency_difference_hz",
            gait.turn_frequency_difference_hz,
        )?;
        let fastest_hz = gait.frequency_hz.abs() + 0.5 * gait.turn_frequency_difference_hz.abs();
        let limit_hz = motor.no_load_speed_rad_s / std::f64::consts::TAU;
        if fastest_hz >= limit_hz {
            return Err(fail(
                "gait.frequency_hz",
                gait.frequency_hz.to_string(),
                &format!(
                    "|frequency_hz| + |turn_frequency_difference_hz|/2 = {fastest_hz} Hz must stay \
                     below the motor's no-load speed {limit_hz:.3} Hz (gait.motor.no_load_speed_rad_s)"
                ),
            ));
        }

        non_negative("ground.friction", self.ground.friction)?;
        let height = self.ground.height_m;
        if !(height.is_finite() && height <= 0.0) {
            return Err(fail(
                "ground.height_m",
                height.to_string(),
                "must be finite and <= 0 (the robot starts just above z = 0)",
            ));
        }

        let phys = &self.physics;
        positive("physics.max_dt_s", phys.max_dt_s)?;
        if phys.max_dt_s > MAX_PHYSICS_DT_S {
            return Err(fail(
                "physics.max_dt_s",
                phys.max_dt_s.to_string(),
                &format!("must be at most {MAX_PHYSICS_DT_S} s"),
            ));
        }
        if !(1..=MAX_SOLVER_ITERATIONS).contains(&phys.solver_iterations) {
            return Err(fail(
                "physics.solver_iterations",
                phys.solver_iterations.to_string(),
                &format!("must be between 1 and {MAX_SOLVER_ITERATIONS}"),
            ));
        }
        positive("physics.length_unit_m", phys.length_unit_m)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn empty_section_takes_the_defaults() {
        let cfg: RobotConfig = serde_yaml_ng::from_str("{}").unwrap();
        assert_eq!(cfg, RobotConfig::default());
        assert_eq!(cfg.gait.frequency_hz, 4.0);
    }

    #[test]
    fn unknown_fields_are_rejected() {
        let err = serde_yaml_ng::from_str::<RobotConfig>("gait: {frequncy_hz: 3}").unwrap_err();
        assert!(err.to_string().contains("frequncy_hz"), "{err}");
    }

    #[test]
    fn out_of_range_values_name_file_and_field() {
        let mut cfg = RobotConfig {
            urdf: PathBuf::from("Cargo.toml"),
            ..Default::default()
        };
        cfg.gait.frequency_hz = 99.0;
        let msg = cfg
            .validate(Path::new("config/x.yaml"))
            .unwrap_err()
            .to_string();
        assert!(
            msg.starts_with("config/x.yaml: robot.gait.frequency_hz = 99"),
            "{msg}"
        );

        let mut cfg = RobotConfig {
            urdf: PathBuf::from("Cargo.toml"),
            ..Default::default()
        };
        cfg.physics.max_dt_s = 0.0;
        let msg = cfg.validate(Path::new("s.yaml")).unwrap_err().to_string();
        assert!(msg.contains("robot.physics.max_dt_s = 0"), "{msg}");

        let cfg = RobotConfig {
            urdf: PathBuf::from("no/such.urdf"),
            ..Default::default()
        };
        let msg = cfg.validate(Path::new("s.yaml")).unwrap_err().to_string();
        assert!(
            msg.contains("robot.urdf = no/such.urdf: file not found"),
            "{msg}"
        );

        // A directory is named as one (issue 22: it was "file not found").
        let cfg = RobotConfig {
            urdf: PathBuf::from("urdf"),
            ..Default::default()
        };
        let msg = cfg.validate(Path::new("s.yaml")).unwrap_err().to_string();
        assert!(msg.contains("robot.urdf = urdf: is a directory"), "{msg}");
    }
}
