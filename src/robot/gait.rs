//! Alternating tripod gait and the torque-limited DC motor model; pure, no rapier.
//!
//! One phase per side advances at that side's frequency (equal when not turning). Tripod A
//! legs target `phase`, tripod B legs `phase + pi`. A positive joint angle turns a leg about
//! +y, sweeping its foot backwards under the hip, which pushes the robot forward.

use std::f64::consts::{PI, TAU};

use super::config::{GaitConfig, MotorConfig};
use super::geometry::{Side, Tripod, LEGS, LEG_COUNT};

/// What the robot is told to do.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct GaitCommand {
    /// Leg rotation frequency (Hz); negative walks backward.
    pub frequency_hz: f64,
    /// Right minus left leg frequency (Hz); positive turns a forward-walking robot left.
    pub turn_frequency_difference_hz: f64,
    /// Direct joint speeds (rad/s), in [`LEGS`] order, bypassing the tripod gait while set:
    /// each joint tracks its own target angle, starting where the joint is and advancing at
    /// this speed. When cleared, each leg resumes the gait at the pattern angle nearest to
    /// where it is.
    pub joint_velocity_override_rad_s: Option<[f64; LEG_COUNT]>,
}

impl GaitCommand {
    /// The command a scene's `robot.gait` section starts with.
    pub fn from_config(gait: &GaitConfig) -> Self {
        Self {
            frequency_hz: gait.frequency_hz,
            turn_frequency_difference_hz: gait.turn_frequency_difference_hz,
            joint_velocity_override_rad_s: None,
        }
    }

    /// Frequency of one side's legs (Hz).
    pub fn side_frequency_hz(&self, side: Side) -> f64 {
        let half = 0.5 * self.turn_frequency_difference_hz;
        match side {
            Side::Left => self.frequency_hz - half,
            Side::Right => self.frequency_hz + half,
        }
    }
}

/// What one leg's motor should do this step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointTarget {
    /// Target angle (rad, unwrapped); `None` for speed-only control.
    pub position_rad: Option<f64>,
    /// Target speed (rad/s).
    pub velocity_rad_s: f64,
}

/// Phase of the tripod gait; advance it, then read the per-leg targets.
#[derive(Debug, Clone, PartialEq)]
pub struct GaitController {
    command: GaitCommand,
    /// Phase of the left and right legs of tripod A (rad, unwrapped).
    side_phase_rad: [f64; 2],
    /// Whole turns (multiples of 2 pi) added to each leg's target, so a leg resumes the gait
    /// near where an override left it (rad).
    turn_offset_rad: [f64; LEG_COUNT],
    /// Per-joint target angles while a velocity override is in force (rad).
    override_target_rad: [f64; LEG_COUNT],
}

impl GaitController {
    /// A gait at phase 0: tripod A straight down (angle 0), tripod B straight up (angle pi).
    pub fn new(command: GaitCommand) -> Self {
        Self {
            command,
            side_phase_rad: [0.0; 2],
            turn_offset_rad: [0.0; LEG_COUNT],
            override_target_rad: [0.0; LEG_COUNT],
        }
    }

    /// The command in force.
    pub fn command(&self) -> &GaitCommand {
        &self.command
    }

    /// Replaces the command. Entering a velocity override starts each joint's target at its
    /// current angle `joint_positions_rad` (rad, [`LEGS`] order); leaving one re-bases each
    /// leg's target to the gait angle nearest its current angle.
    pub fn set_command(&mut self, command: GaitCommand, joint_positions_rad: &[f64; LEG_COUNT]) {
        let was_overriding = self.command.joint_velocity_override_rad_s.is_some();
        let overriding = command.joint_velocity_override_rad_s.is_some();
        let leaving_override = was_overriding && !overriding;
        if overriding && !was_overriding {
            self.override_target_rad = *joint_positions_rad;
        }
        self.command = command;
        if leaving_override {
            for (i, q) in joint_positions_rad.iter().enumerate() {
                let pattern = self.pattern_angle_rad(i);
                self.turn_offset_rad[i] = TAU * ((q - pattern) / TAU).round();
            }
        }
    }

    /// Advances the phases by `dt_s` seconds at the commanded side frequencies (and the
    /// override targets at their speeds).
    pub fn advance(&mut self, dt_s: f64) {
        if let Some(v) = self.command.joint_velocity_override_rad_s {
            for (target, speed) in self.override_target_rad.iter_mut().zip(v) {
                *target += speed * dt_s;
            }
        }
        for (phase, side) in self
            .side_phase_rad
            .iter_mut()
            .zip([Side::Left, Side::Right])
        {
            *phase += TAU * self.command.side_frequency_hz(side) * dt_s;
        }
    }

    /// Commanded phase of the left and right legs of tripod A (rad, unwrapped).
    pub fn side_phase_rad(&self) -> [f64; 2] {
        self.side_phase_rad
    }

    /// Target of leg `i` ([`LEGS`] order).
    pub fn target(&self, i: usize) -> JointTarget {
        if let Some(v) = self.command.joint_velocity_override_rad_s {
            return JointTarget {
                position_rad: Some(self.override_target_rad[i]),
                velocity_rad_s: v[i],
            };
        }
        JointTarget {
            position_rad: Some(self.pattern_angle_rad(i) + self.turn_offset_rad[i]),
            velocity_rad_s: TAU * self.command.side_frequency_hz(LEGS[i].side),
        }
    }

    /// The gait's angle for leg `i` before whole-turn offsets (rad).
    fn pattern_angle_rad(&self, i: usize) -> f64 {
        let leg = &LEGS[i];
        let side = match leg.side {
            Side::Left => 0,
            Side::Right => 1,
        };
        let tripod_offset = match leg.tripod {
            Tripod::A => 0.0,
            Tripod::B => PI,
        };
        self.side_phase_rad[side] + tripod_offset
    }
}

/// A DC motor behind a PD phase controller.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DcMotor {
    /// Torque at zero speed (N m).
    pub stall_torque_n_m: f64,
    /// Speed at which the driving torque reaches zero (rad/s).
    pub no_load_speed_rad_s: f64,
    /// PD stiffness (N m/rad).
    pub position_gain_n_m_per_rad: f64,
    /// PD damping (N m s/rad).
    pub velocity_gain_n_m_s_per_rad: f64,
}

impl From<&MotorConfig> for DcMotor {
    fn from(m: &MotorConfig) -> Self {
        Self {
            stall_torque_n_m: m.stall_torque_n_m,
            no_load_speed_rad_s: m.no_load_speed_rad_s,
            position_gain_n_m_per_rad: m.position_gain_n_m_per_rad,
            velocity_gain_n_m_s_per_rad: m.velocity_gain_n_m_s_per_rad,
        }
    }
}

impl DcMotor {
    /// The PD torque towards `target` from angle `q_rad` and speed `w_rad_s`, before limits.
    pub fn pd_torque_n_m(&self, target: &JointTarget, q_rad: f64, w_rad_s: f64) -> f64 {
        let spring = target
            .position_rad
            .map_or(0.0, |qt| self.position_gain_n_m_per_rad * (qt - q_rad));
        spring + self.velocity_gain_n_m_s_per_rad * (target.velocity_rad_s - w_rad_s)
    }

    /// Largest torque magnitude available at speed `w_rad_s` for a torque of sign
    /// `desired_n_m`: driving (torque along the motion) follows the torque-speed line
    /// `stall (1 - |w| / no_load)`, clamped at 0; braking gets the stall torque.
    pub fn torque_limit_n_m(&self, w_rad_s: f64, desired_n_m: f64) -> f64 {
        let driving = desired_n_m * w_rad_s > 0.0;
        if driving {
            self.stall_torque_n_m * (1.0 - w_rad_s.abs() / self.no_load_speed_rad_s).max(0.0)
        } else {
            self.stall_torque_n_m
        }
    }

    /// The torque this motor applies: the PD torque clipped to the available torque.
    pub fn torque_n_m(&self, target: &JointTarget, q_rad: f64, w_rad_s: f64) -> f64 {
        let tau = self.pd_torque_n_m(target, q_rad, w_rad_s);
        let limit = self.torque_limit_n_m(w_rad_s, tau);
        tau.clamp(-limit, limit)
    }
}

/// Wraps an angle to [0, 2 pi).
pub fn wrap_to_tau(a: f64) -> f64 {
    a.rem_euclid(TAU)
}

/// Wraps an angle to (-pi, pi].
pub fn wrap_to_pi(a: f64) -> f64 {
    let w = a.rem_euclid(TAU);
    if w > PI {
        w - TAU
    } else {
        w
    }
}

/// Circular mean of angles (rad), in [0, 2 pi).
pub fn circular_mean(angles: impl IntoIterator<Item = f64>) -> f64 {
    let (s, c) = angles
        .into_iter()
        .fold((0.0, 0.0), |(s, c), a| (s + libm::sin(a), c + libm::cos(a)));
    wrap_to_tau(libm::atan2(s, c))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cmd(f: f64, df: f64) -> GaitCommand {
        GaitCommand {
            frequency_hz: f,
            turn_frequency_difference_hz: df,
            joint_velocity_override_rad_s: None,
        }
    }

    #[test]
    fn tripods_are_half_a_cycle_apart_and_advance_at_the_frequency() {
        let mut g = GaitController::new(cmd(4.0, 0.0));
        g.advance(0.1);
        for (i, leg) in LEGS.iter().enumerate() {
            let t = g.target(i);
            let want = TAU * 4.0 * 0.1 + if leg.tripod == Tripod::B { PI } else { 0.0 };
            assert!(
                (t.position_rad.unwrap() - want).abs() < 1e-12,
                "{}",
                leg.stem
            );
            assert!((t.velocity_rad_s - TAU * 4.0).abs() < 1e-12);
        }
    }

    #[test]
    fn turning_runs_the_right_side_faster() {
        let mut g = GaitController::new(cmd(2.0, 1.0));
        g.advance(1.0);
        let [l, r] = g.side_phase_rad();
        assert!((l - TAU * 1.5).abs() < 1e-12 && (r - TAU * 2.5).abs() < 1e-12);
    }

    #[test]
    fn leaving_an_override_resumes_the_nearest_pattern_angle() {
        let mut g = GaitController::new(cmd(1.0, 0.0));
        let over = GaitCommand {
            joint_velocity_override_rad_s: Some([3.0; LEG_COUNT]),
            ..cmd(1.0, 0.0)
        };
        g.set_command(over, &[0.5; LEG_COUNT]);
        g.advance(0.1);
        let t = g.target(0);
        assert!(
            (t.position_rad.unwrap() - 0.8).abs() < 1e-12 && t.velocity_rad_s == 3.0,
            "{t:?}"
        );
        // Leg 0 (tripod A) ended two turns and a bit beyond the gait's phase, leg 1
        // (tripod B) a little short of it.
        let phase = g.side_phase_rad()[0];
        let mut q = [0.0; LEG_COUNT];
        q[0] = phase + 2.0 * TAU + 0.2;
        q[1] = phase + PI - 0.1;
        g.set_command(cmd(1.0, 0.0), &q);
        assert!((g.target(0).position_rad.unwrap() - (phase + 2.0 * TAU)).abs() < 1e-12);
        assert!((g.target(1).position_rad.unwrap() - (phase + PI)).abs() < 1e-12);
    }

    #[test]
    fn motor_follows_the_torque_speed_line() {
        let m = DcMotor {
            stall_torque_n_m: 0.1,
            no_load_speed_rad_s: 50.0,
            position_gain_n_m_per_rad: 1.0,
            velocity_gain_n_m_s_per_rad: 0.0,
        };
        let far_ahead = JointTarget {
            position_rad: Some(10.0),
            velocity_rad_s: 0.0,
        };
        assert!((m.torque_n_m(&far_ahead, 0.0, 0.0) - 0.1).abs() < 1e-12);
        assert!((m.torque_n_m(&far_ahead, 0.0, 25.0) - 0.05).abs() < 1e-12);
        assert_eq!(m.torque_n_m(&far_ahead, 0.0, 60.0), 0.0);
        // Braking against the motion: full stall torque.
        assert!((m.torque_n_m(&far_ahead, 0.0, -25.0) - 0.1).abs() < 1e-12);
        let small = JointTarget {
            position_rad: Some(0.01),
            velocity_rad_s: 0.0,
        };
        assert!((m.torque_n_m(&small, 0.0, 0.0) - 0.01).abs() < 1e-12);
    }

    #[test]
    fn angle_helpers() {
        assert!((wrap_to_pi(3.0 * PI / 2.0) + PI / 2.0).abs() < 1e-12);
        assert!((wrap_to_tau(-0.5) - (TAU - 0.5)).abs() < 1e-12);
        assert!(
            (circular_mean([TAU - 0.1, 0.1]) - 0.0).abs() < 1e-12
                || (circular_mean([TAU - 0.1, 0.1]) - TAU).abs() < 1e-12
        );
    }
}
