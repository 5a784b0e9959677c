//! The terrain's load on the robot's body and on each leg, summed over steps and reported as a
//! mean wrench in each link's frame (`body_wrench` and `leg_wrenches` of the node and the bag).

use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use rapier3d::prelude::{RigidBody, RigidBodyHandle};

use crate::robot::geometry::{BODY_LINK, LEGS};
use crate::robot::{RobotSim, LEG_COUNT};

/// A terrain's impulse on one rigid body over one step: linear (N s) and angular about the
/// body's centre of mass (N m s), world axes.
#[derive(Clone, Copy, Debug)]
pub struct BodyImpulse {
    pub body: RigidBodyHandle,
    pub linear_n_s: Vector3<f64>,
    pub angular_n_m_s: Vector3<f64>,
}

/// An impulse (N s) and an angular impulse about a link's origin (a leg's hip, the body's
/// centre) (N m s), world axes.
#[derive(Clone, Copy, Debug, Default)]
struct ImpulseSum {
    linear_n_s: Vector3<f64>,
    angular_n_m_s: Vector3<f64>,
}

/// The terrain's mean force and torque on one link over an interval, in the link's frame.
#[derive(Clone, Debug, PartialEq)]
pub struct LinkWrench {
    /// URDF link name.
    pub link: String,
    /// Force (N), link frame.
    pub force_n: [f64; 3],
    /// Torque about the link origin (a leg's hip axis, the body's centre) (N m), link frame.
    pub torque_n_m: [f64; 3],
}

/// The terrain's mean wrench on the body (its belly and sides) and on each leg over an
/// interval. Their vertical forces together carry the robot's weight on average.
#[derive(Clone, Debug, PartialEq)]
pub struct TerrainWrenches {
    /// On the root link (`base_link`).
    pub body: LinkWrench,
    /// On each leg, in [`LEGS`] order.
    pub legs: Vec<LinkWrench>,
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

/// The body's and the legs' impulses summed since the last report, and the time they were
/// summed over.
#[derive(Clone, Debug, Default)]
pub struct TerrainLoads {
    body: ImpulseSum,
    legs: [ImpulseSum; LEG_COUNT],
    /// Simulated time summed over (s).
    time_s: f64,
}

impl TerrainLoads {
    /// Adds one step of `dt_s` seconds: each impulse on the body's or a leg's rigid body,
    /// moved from its centre of mass to the link origin (a leg's hip), `L_o = L_com + (com - o)
    /// x J`, with the links where they are before the step moves them.
    pub fn add_step(&mut self, robot: &RobotSim, impulses: &[BodyImpulse], dt_s: f64) {
        let bodies = &robot.world().bodies;
        let links = std::iter::once((&mut self.body, robot.body_handle()))
            .chain(self.legs.iter_mut().zip(robot.leg_handles()));
        for (sum, h) in links {
            for j in impulses.iter().filter(|j| j.body == h) {
                add_at_link_origin(&bodies[h], j.linear_n_s, j.angular_n_m_s, sum);
            }
        }
        self.time_s += dt_s;
    }

    /// The mean wrench on the body and on each leg since the last call, each in its link's
    /// frame (zero when no time has passed); starts the sums again.
    pub fn take_mean(&mut self, robot: &RobotSim) -> TerrainWrenches {
        let elapsed = self.time_s;
        let bodies = &robot.world().bodies;
        let mean_wrench = |link: String, h: RigidBodyHandle, sum: &ImpulseSum| {
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
            LinkWrench {
                link,
                force_n: mean(sum.linear_n_s),
                torque_n_m: mean(sum.angular_n_m_s),
            }
        };
        let wrenches = TerrainWrenches {
            body: mean_wrench(BODY_LINK.to_string(), robot.body_handle(), &self.body),
            legs: LEGS
                .iter()
                .zip(robot.leg_handles())
                .zip(&self.legs)
                .map(|((leg, h), sum)| mean_wrench(leg.link_name(), h, sum))
                .collect(),
        };
        *self = TerrainLoads::default();
        wrenches
    }
}
