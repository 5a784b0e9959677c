//! The terrain's load on each leg, summed over steps and reported as a mean wrench in the leg's
//! frame (`leg_wrenches` of the node and the bag).

use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use rapier3d::prelude::{RigidBody, RigidBodyHandle};

use crate::robot::geometry::LEGS;
use crate::robot::{RobotSim, LEG_COUNT};

/// A terrain's impulse on one rigid body over one step: linear (N s) and angular about the
/// body's centre of mass (N m s), world axes.
#[derive(Clone, Copy, Debug)]
pub struct BodyImpulse {
    pub body: RigidBodyHandle,
    pub linear_n_s: Vector3<f64>,
    pub angular_n_m_s: Vector3<f64>,
}

/// An impulse (N s) and an angular impulse about a leg's link origin, its hip (N m s), world
/// axes.
#[derive(Clone, Copy, Debug, Default)]
struct ImpulseSum {
    linear_n_s: Vector3<f64>,
    angular_n_m_s: Vector3<f64>,
}

/// The sand's mean force and torque on one leg over an interval, in the leg link's frame.
#[derive(Clone, Debug, PartialEq)]
pub struct LegWrench {
    /// URDF link name of the leg.
    pub link: String,
    /// Force (N), leg link frame.
    pub force_n: [f64; 3],
    /// Torque about the link origin (the hip axis) (N m), leg link frame.
    pub torque_n_m: [f64; 3],
}

/// Adds an impulse (N s) and an angular impulse about the body's centre of mass (N m s), world
/// axes, to `sum`, moved to the link origin.
fn add_at_link_origin(
    rb: &RigidBody,
    linear_n_s: Vector3<f64>,
    angular_com_n_m_s: Vector3<f64>,
    sum: &mut ImpulseSum,
) {
    let com = rb.center_of_mass();
    let origin = rb.position().translation;
    let arm = Vector3::new(
        (com.x - origin.x) as f64,
        (com.y - origin.y) as f64,
        (com.z - origin.z) as f64,
    );
    sum.linear_n_s += linear_n_s;
    sum.angular_n_m_s += angular_com_n_m_s + arm.cross(&linear_n_s);
}

/// The legs' impulses summed since the last report, and the time they were summed over.
#[derive(Clone, Debug, Default)]
pub struct LegLoads {
    sums: [ImpulseSum; LEG_COUNT],
    /// Simulated time summed over (s).
    time_s: f64,
}

impl LegLoads {
    /// Adds one step of `dt_s` seconds: each impulse on a leg's body, moved from the body's
    /// centre of mass to the leg's link origin (its hip), `L_o = L_com + (com - o) x J`, with
    /// the links where they are before the step moves them.
    pub fn add_step(&mut self, robot: &RobotSim, impulses: &[BodyImpulse], dt_s: f64) {
        let bodies = &robot.world().bodies;
        for (sum, &h) in self.sums.iter_mut().zip(robot.leg_handles().iter()) {
            for j in impulses.iter().filter(|j| j.body == h) {
                add_at_link_origin(&bodies[h], j.linear_n_s, j.angular_n_m_s, sum);
            }
        }
        self.time_s += dt_s;
    }

    /// The mean wrench on each leg since the last call, in each leg link's frame (zero when no
    /// time has passed); starts the sums again.
    pub fn take_mean(&mut self, robot: &RobotSim) -> Vec<LegWrench> {
        let elapsed = self.time_s;
        let bodies = &robot.world().bodies;
        let wrenches = LEGS
            .iter()
            .zip(robot.leg_handles())
            .zip(&self.sums)
            .map(|((leg, h), sum)| {
                let r = bodies[h].position().rotation;
                let to_link = UnitQuaternion::from_quaternion(Quaternion::new(
                    r.w as f64, r.x as f64, r.y as f64, r.z as f64,
                ))
                .inverse();
                let mean = |v: Vector3<f64>| {
                    let v = to_link * v / elapsed.max(f64::MIN_POSITIVE);
                    if elapsed > 0.0 {
                        [v.x, v.y, v.z]
                    } else {
                        [0.0; 3]
                    }
                };
                LegWrench {
                    link: leg.link_name(),
                    force_n: mean(sum.linear_n_s),
                    torque_n_m: mean(sum.angular_n_m_s),
                }
            })
            .collect();
        *self = LegLoads::default();
        wrenches
    }
}
