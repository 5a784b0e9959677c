//! Commands from controllers to gait commands: `gait/frequency`, `cmd_vel` and
//! `leg_velocity_controller/commands` (the ros2_control forward-command convention). The newest
//! command wins; one older than the timeout gives way to the scene's default gait. Pure: no DDS.

use crate::msgs::{Float64, Float64MultiArray, Twist};
use crate::robot::{GaitCommand, LEG_COUNT};
use crate::scene::config::NodeConfig;

/// A command as received.
#[derive(Clone, Debug, PartialEq)]
pub enum Command {
    /// `gait/frequency`: leg frequency (Hz), sign = direction.
    GaitFrequency(Float64),
    /// `cmd_vel`: linear.x (m/s) and angular.z (rad/s).
    CmdVel(Twist),
    /// `leg_velocity_controller/commands`: rad/s per leg joint in URDF order.
    LegVelocities(Float64MultiArray),
}

/// Why a command was not applied.
#[derive(thiserror::Error, Debug, PartialEq)]
pub enum CommandError {
    #[error("leg_velocity_controller/commands: {got} values, expected {LEG_COUNT} (rad/s per leg joint, in the order of joint_states)")]
    WrongLength { got: usize },
    #[error("{topic}: value {value} is not finite")]
    NotFinite { topic: &'static str, value: f64 },
}

/// The gait command in force and where it came from.
#[derive(Clone, Debug)]
pub struct CommandState {
    default: GaitCommand,
    stride_length_m: f64,
    track_width_m: f64,
    /// Commands expire after this long (s of simulated time); 0 = never.
    timeout_s: f64,
    current: GaitCommand,
    /// Simulated time of the last applied command (s); `None` while on the default.
    last_command_s: Option<f64>,
}

impl CommandState {
    /// Starts on `default` (the scene's gait).
    pub fn new(default: GaitCommand, node: &NodeConfig) -> Self {
        Self {
            default,
            stride_length_m: node.stride_length_m,
            track_width_m: node.track_width_m,
            timeout_s: node.command_timeout_s,
            current: default,
            last_command_s: None,
        }
    }

    /// The gait command `cmd` asks for.
    pub fn gait_command(&self, cmd: &Command) -> Result<GaitCommand, CommandError> {
        let finite = |topic, value: f64| {
            if value.is_finite() {
                Ok(value)
            } else {
                Err(CommandError::NotFinite { topic, value })
            }
        };
        Ok(match cmd {
            Command::GaitFrequency(f) => GaitCommand {
                frequency_hz: finite("gait/frequency", f.data)?,
                ..GaitCommand::default()
            },
            Command::CmdVel(t) => {
                let v = finite("cmd_vel linear.x", t.linear.x)?;
                let w = finite("cmd_vel angular.z", t.angular.z)?;
                GaitCommand {
                    frequency_hz: v / self.stride_length_m,
                    // Right minus left speed is w * track; each side's speed is f * stride.
                    turn_frequency_difference_hz: w * self.track_width_m / self.stride_length_m,
                    joint_velocity_override_rad_s: None,
                }
            }
            Command::LegVelocities(a) => {
                let speeds: [f64; LEG_COUNT] = a
                    .data
                    .as_slice()
                    .try_into()
                    .map_err(|_| CommandError::WrongLength { got: a.data.len() })?;
                for s in speeds {
                    finite("leg_velocity_controller/commands", s)?;
                }
                GaitCommand {
                    joint_velocity_override_rad_s: Some(speeds),
                    ..GaitCommand::default()
                }
            }
        })
    }

    /// Applies `cmd` received at `now_s` (s of simulated time); returns the new command.
    pub fn receive(&mut self, cmd: &Command, now_s: f64) -> Result<GaitCommand, CommandError> {
        self.current = self.gait_command(cmd)?;
        self.last_command_s = Some(now_s);
        Ok(self.current)
    }

    /// At a control tick: falls back to the default once the last command has expired.
    /// Returns the command to give the robot when it changed.
    pub fn tick(&mut self, now_s: f64) -> Option<GaitCommand> {
        let last = self.last_command_s?;
        if self.timeout_s > 0.0 && now_s - last > self.timeout_s {
            self.last_command_s = None;
            self.current = self.default;
            return Some(self.current);
        }
        None
    }

    /// Back to the default (after a reset).
    pub fn reset(&mut self) {
        self.current = self.default;
        self.last_command_s = None;
    }

    /// The command in force.
    pub fn current(&self) -> GaitCommand {
        self.current
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msgs::Vector3;

    fn state() -> CommandState {
        let default = GaitCommand {
            frequency_hz: 2.0,
            ..GaitCommand::default()
        };
        CommandState::new(default, &NodeConfig::default())
    }

    #[test]
    fn cmd_vel_maps_through_stride_and_track() {
        let s = state();
        let twist = Twist {
            linear: Vector3 {
                x: 0.3,
                ..Default::default()
            },
            angular: Vector3 {
                z: 2.0,
                ..Default::default()
            },
        };
        let g = s.gait_command(&Command::CmdVel(twist)).unwrap();
        // stride 0.1 m, track 0.05 m
        assert!((g.frequency_hz - 3.0).abs() < 1e-12);
        assert!((g.turn_frequency_difference_hz - 1.0).abs() < 1e-12);
    }

    #[test]
    fn commands_expire_to_the_default() {
        let mut s = state();
        let g = s
            .receive(&Command::GaitFrequency(Float64 { data: -1.5 }), 10.0)
            .unwrap();
        assert_eq!(g.frequency_hz, -1.5);
        assert_eq!(s.tick(10.9), None);
        assert_eq!(s.tick(11.01).map(|g| g.frequency_hz), Some(2.0));
        assert_eq!(s.tick(20.0), None, "the fallback happens once");
    }

    #[test]
    fn leg_velocities_need_one_value_per_joint() {
        let mut s = state();
        let bad = Float64MultiArray {
            data: vec![1.0; 5],
            ..Default::default()
        };
        assert_eq!(
            s.receive(&Command::LegVelocities(bad), 0.0),
            Err(CommandError::WrongLength { got: 5 })
        );
        assert_eq!(
            s.current().frequency_hz,
            2.0,
            "a bad command changes nothing"
        );
        let good = Float64MultiArray {
            data: vec![3.0; LEG_COUNT],
            ..Default::default()
        };
        let g = s.receive(&Command::LegVelocities(good), 0.0).unwrap();
        assert_eq!(g.joint_velocity_override_rad_s, Some([3.0; LEG_COUNT]));
        assert!(s
            .receive(&Command::GaitFrequency(Float64 { data: f64::NAN }), 0.0)
            .is_err());
    }
}
