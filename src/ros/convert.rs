//! Plain simulation outputs to ROS 2 messages (REP-103 axes, REP-105 frames `odom` and
//! `base_link`). Pure functions: no DDS, no bag.

use nalgebra::{Quaternion as NaQuaternion, UnitQuaternion, Vector3 as NaVector3};

use crate::msgs::{
    Clock, Header, JointState, Odometry, PointCloud2, Pose, PoseStamped, PoseWithCovariance,
    TFMessage, Time, Transform, TransformStamped, Twist, TwistWithCovariance, Wrench,
    WrenchStamped,
};
use crate::robot::RobotState;
use crate::scene::{LinkPose, LinkWrench};

/// The world-fixed frame of REP-105; the simulator's odometry is ground truth in it.
pub const ODOM_FRAME: &str = "odom";
/// The robot body's frame (REP-105).
pub const BASE_FRAME: &str = "base_link";
/// The map frame; it coincides with `odom` because the odometry has no drift.
pub const MAP_FRAME: &str = "map";

fn unit_quaternion(xyzw: [f64; 4]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(NaQuaternion::new(xyzw[3], xyzw[0], xyzw[1], xyzw[2]))
}

fn xyzw(q: &UnitQuaternion<f64>) -> [f64; 4] {
    [q.i, q.j, q.k, q.w]
}

pub fn clock(stamp: Time) -> Clock {
    Clock { clock: stamp }
}

/// Joint names from the URDF; position (rad), velocity (rad/s), effort (N m).
pub fn joint_state(stamp: Time, robot: &RobotState) -> JointState {
    JointState {
        header: Header::new(stamp, ""),
        name: robot.joint_names.clone(),
        position: robot.joint_positions_rad.clone(),
        velocity: robot.joint_velocities_rad_s.clone(),
        effort: robot.joint_efforts_n_m.clone(),
    }
}

fn body_pose_msg(robot: &RobotState) -> Pose {
    Pose {
        position: robot.base_position_m.into(),
        orientation: robot.base_orientation_xyzw.into(),
    }
}

/// `odom` to `base_link`: pose in `odom`, twist in `base_link` (the nav_msgs convention).
/// Covariances are zero: the simulator knows the pose exactly.
pub fn odometry(stamp: Time, robot: &RobotState) -> Odometry {
    let to_body = unit_quaternion(robot.base_orientation_xyzw).inverse();
    let in_body = |v: [f64; 3]| {
        let b = to_body * NaVector3::from(v);
        [b.x, b.y, b.z].into()
    };
    Odometry {
        header: Header::new(stamp, ODOM_FRAME),
        child_frame_id: BASE_FRAME.into(),
        pose: PoseWithCovariance {
            pose: body_pose_msg(robot),
            covariance: [0.0; 36],
        },
        twist: TwistWithCovariance {
            twist: Twist {
                linear: in_body(robot.base_linear_velocity_m_s),
                angular: in_body(robot.base_angular_velocity_rad_s),
            },
            covariance: [0.0; 36],
        },
    }
}

/// The body pose in `odom`.
pub fn body_pose(stamp: Time, robot: &RobotState) -> PoseStamped {
    PoseStamped {
        header: Header::new(stamp, ODOM_FRAME),
        pose: body_pose_msg(robot),
    }
}

/// `odom` to `base_link` (the first pose), then `base_link` to every other link.
pub fn tf(stamp: Time, links: &[LinkPose]) -> TFMessage {
    let Some((base, others)) = links.split_first() else {
        return TFMessage::default();
    };
    let base_rotation = unit_quaternion(base.orientation_xyzw);
    let base_position = NaVector3::from(base.position_m);
    let stamped =
        |parent: &str, child: &str, translation: NaVector3<f64>, rotation| TransformStamped {
            header: Header::new(stamp, parent),
            child_frame_id: child.into(),
            transform: Transform {
                translation: [translation.x, translation.y, translation.z].into(),
                rotation: xyzw(&rotation).into(),
            },
        };
    std::iter::once(stamped(
        ODOM_FRAME,
        BASE_FRAME,
        base_position,
        base_rotation,
    ))
    .chain(others.iter().map(|link| {
        let to_base = base_rotation.inverse();
        let translation = to_base * (NaVector3::from(link.position_m) - base_position);
        let rotation = to_base * unit_quaternion(link.orientation_xyzw);
        stamped(BASE_FRAME, &link.link, translation, rotation)
    }))
    .collect::<Vec<_>>()
    .into()
}

impl From<Vec<TransformStamped>> for TFMessage {
    fn from(transforms: Vec<TransformStamped>) -> Self {
        TFMessage { transforms }
    }
}

/// `map` to `odom`, identity: the simulator's odometry is exact.
pub fn tf_static(stamp: Time) -> TFMessage {
    vec![TransformStamped {
        header: Header::new(stamp, MAP_FRAME),
        child_frame_id: ODOM_FRAME.into(),
        transform: Transform::default(),
    }]
    .into()
}

/// The terrain's wrench on one link (a leg, the body), in the link's frame.
pub fn link_wrench(stamp: Time, wrench: &LinkWrench) -> WrenchStamped {
    WrenchStamped {
        header: Header::new(stamp, &wrench.link),
        wrench: Wrench {
            force: wrench.force_n.into(),
            torque: wrench.torque_n_m.into(),
        },
    }
}

/// The top of the sand as an unordered `xyz` cloud in `odom`.
pub fn sand_surface(stamp: Time, points: &[[f32; 3]]) -> PointCloud2 {
    PointCloud2::from_points(Header::new(stamp, ODOM_FRAME), points)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn state(yaw_rad: f64) -> RobotState {
        let (s, c) = ((yaw_rad / 2.0).sin(), (yaw_rad / 2.0).cos());
        RobotState {
            time_s: 1.0,
            base_position_m: [1.0, 2.0, 0.1],
            base_orientation_xyzw: [0.0, 0.0, s, c],
            base_linear_velocity_m_s: [0.0, 0.3, 0.0],
            base_angular_velocity_rad_s: [0.0, 0.0, 0.5],
            joint_names: vec!["j".into()],
            joint_positions_rad: vec![0.5],
            joint_velocities_rad_s: vec![1.0],
            joint_efforts_n_m: vec![0.01],
            tripod_phase_rad: [0.0, 0.0],
        }
    }

    #[test]
    fn odometry_twist_is_in_the_body_frame() {
        // Facing +y (yaw 90 deg) and moving along world +y: forward in base_link.
        let odom = odometry(Time::from_secs(1.0), &state(std::f64::consts::FRAC_PI_2));
        let v = odom.twist.twist.linear;
        assert!((v.x - 0.3).abs() < 1e-12 && v.y.abs() < 1e-12, "{v:?}");
        assert!((odom.twist.twist.angular.z - 0.5).abs() < 1e-12);
        assert_eq!(odom.header.frame_id, "odom");
        assert_eq!(odom.child_frame_id, "base_link");
        assert_eq!(odom.pose.pose.position.x, 1.0);
    }

    #[test]
    fn tf_gives_legs_relative_to_the_body() {
        let q = [0.0, 0.0, (0.25f64).sin(), (0.25f64).cos()]; // yaw 0.5 rad
        let base = LinkPose {
            link: "base_link".into(),
            position_m: [1.0, 0.0, 0.2],
            orientation_xyzw: q,
        };
        // A leg 5 cm along the body's x axis, same orientation.
        let leg = LinkPose {
            link: "leg_a".into(),
            position_m: [1.0 + 0.05 * 0.5f64.cos(), 0.05 * 0.5f64.sin(), 0.2],
            orientation_xyzw: q,
        };
        let msg = tf(Time::default(), &[base, leg]);
        assert_eq!(msg.transforms.len(), 2);
        assert_eq!(msg.transforms[0].header.frame_id, "odom");
        let t = &msg.transforms[1];
        assert_eq!(
            (t.header.frame_id.as_str(), t.child_frame_id.as_str()),
            ("base_link", "leg_a")
        );
        let tr = t.transform.translation;
        assert!((tr.x - 0.05).abs() < 1e-12 && tr.y.abs() < 1e-12 && tr.z.abs() < 1e-12);
        assert!((t.transform.rotation.w - 1.0).abs() < 1e-12);
    }
}
