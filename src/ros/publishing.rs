//! What the simulator publishes, when, and where to: every message goes to the bag (if
//! recording) and to DDS (if running as a node). `sandstep run` uses this without DDS.

use std::path::{Path, PathBuf};

use ros2_client::{MessageTypeName, Name, Node, Publisher};

use super::convert;
use super::qos;
use crate::bag::{BagInfo, BagWriter, Durability};
use crate::msgs::{
    Clock, JointState, Odometry, PointCloud2, PoseStamped, RosMessage, StringMsg, TFMessage, Time,
    WrenchStamped,
};
use crate::scene::{Observer, Scene, Simulation};

/// Topics outside the node's namespace (ROS conventions).
pub const CLOCK_TOPIC: &str = "/clock";
pub const TF_TOPIC: &str = "/tf";
pub const TF_STATIC_TOPIC: &str = "/tf_static";
/// Relative topics, in the node's namespace.
pub const JOINT_STATES_TOPIC: &str = "joint_states";
pub const ODOM_TOPIC: &str = "odom";
pub const BODY_POSE_TOPIC: &str = "body_pose";
pub const ROBOT_DESCRIPTION_TOPIC: &str = "robot_description";
pub const LEG_WRENCHES_TOPIC: &str = "leg_wrenches";
pub const BODY_WRENCH_TOPIC: &str = "body_wrench";
pub const SAND_SURFACE_TOPIC: &str = "sand/surface";

/// `name` resolved in `namespace` (absolute names stay as they are).
pub fn resolve(namespace: &str, name: &str) -> String {
    if name.starts_with('/') {
        name.to_string()
    } else {
        format!("{}/{name}", namespace.trim_end_matches('/'))
    }
}

/// Why publishing or recording failed.
#[derive(thiserror::Error, Debug)]
pub enum PublishError {
    #[error(transparent)]
    Bag(#[from] crate::bag::BagError),
    #[error("ROS 2: cannot create {what}: {message}")]
    Create { what: String, message: String },
    #[error("cannot read the robot's URDF {}: {cause}", path.display())]
    Urdf {
        path: PathBuf,
        cause: std::io::Error,
    },
}

/// One outgoing topic: its resolved name, QoS durability and, in a node, its DDS publisher.
pub struct Topic<M: RosMessage> {
    pub name: String,
    pub durability: Durability,
    publisher: Option<Publisher<M>>,
}

impl<M: RosMessage> Topic<M> {
    fn new(
        name: String,
        durability: Durability,
        node: Option<&mut Node>,
    ) -> Result<Self, PublishError> {
        let publisher = match node {
            None => None,
            Some(node) => Some(create_publisher::<M>(node, &name, durability)?),
        };
        Ok(Topic {
            name,
            durability,
            publisher,
        })
    }
}

/// A DDS publisher of `M` on the absolute topic `name`.
pub fn create_publisher<M: RosMessage>(
    node: &mut Node,
    name: &str,
    durability: Durability,
) -> Result<Publisher<M>, PublishError> {
    let fail = |e: &dyn std::fmt::Display| PublishError::Create {
        what: format!("publisher {name}"),
        message: e.to_string(),
    };
    let qos = qos::publisher(durability);
    let ros_name = Name::parse(name).map_err(|e| fail(&format!("{e:?}")))?;
    let ty = M::TYPE;
    let topic = node
        .create_topic(&ros_name, MessageTypeName::new(ty.package, ty.name), &qos)
        .map_err(|e| fail(&e))?;
    node.create_publisher(&topic, Some(qos))
        .map_err(|e| fail(&e))
}

/// All topics the simulator publishes.
struct Topics {
    clock: Topic<Clock>,
    joint_states: Topic<JointState>,
    odom: Topic<Odometry>,
    body_pose: Topic<PoseStamped>,
    tf: Topic<TFMessage>,
    tf_static: Topic<TFMessage>,
    robot_description: Topic<StringMsg>,
    /// The terrain's wrench on the body; `None` on rigid ground or without a robot.
    body_wrench: Option<Topic<WrenchStamped>>,
    leg_wrenches: Vec<Topic<WrenchStamped>>,
    sand_surface: Topic<PointCloud2>,
}

/// Publishes and records the simulation's outputs at their rates.
pub struct Publishing {
    topics: Topics,
    bag: Option<BagWriter>,
    /// Period of the robot state topics and `/clock` (s).
    state_period_s: f64,
    /// Period of `sand/surface` (s); infinite = never.
    surface_period_s: f64,
    surface_cell_m: f32,
    next_state_s: f64,
    next_surface_s: f64,
    /// The URDF text for `robot_description`.
    urdf: Option<String>,
    /// Added to the simulation's time in every stamp (s), so that the clock keeps running
    /// forward across resets.
    pub time_offset_s: f64,
}

/// Tolerance when comparing a simulated time with a due time (s).
const DUE_TOLERANCE_S: f64 = 1e-9;

impl Publishing {
    /// The topics of `scene` as it is built in `sim`, with DDS publishers when `node` is given
    /// and recording into `bag` when given.
    pub fn new(
        scene: &Scene,
        sim: &Simulation,
        node: Option<&mut Node>,
        bag: Option<BagWriter>,
    ) -> Result<Self, PublishError> {
        let cfg = &scene.config.node;
        let ns = cfg.namespace.as_str();
        let mut node = node;
        macro_rules! make {
            ($name:expr, $durability:expr) => {
                Topic::new(resolve(ns, $name), $durability, node.as_deref_mut())?
            };
        }
        let leg_links: Vec<String> = sim
            .link_poses()
            .into_iter()
            .skip(1)
            .map(|l| l.link)
            .collect();
        let mut leg_wrenches = Vec::new();
        let mut body_wrench = None;
        if sim.has_terrain_wrenches() {
            body_wrench = Some(make!(BODY_WRENCH_TOPIC, Durability::Volatile));
            for link in &leg_links {
                leg_wrenches.push(make!(
                    &format!("{LEG_WRENCHES_TOPIC}/{link}"),
                    Durability::Volatile
                ));
            }
        }
        let topics = Topics {
            clock: make!(CLOCK_TOPIC, Durability::Volatile),
            joint_states: make!(JOINT_STATES_TOPIC, Durability::Volatile),
            odom: make!(ODOM_TOPIC, Durability::Volatile),
            body_pose: make!(BODY_POSE_TOPIC, Durability::Volatile),
            tf: make!(TF_TOPIC, Durability::Volatile),
            tf_static: make!(TF_STATIC_TOPIC, Durability::TransientLocal),
            robot_description: make!(ROBOT_DESCRIPTION_TOPIC, Durability::TransientLocal),
            body_wrench,
            leg_wrenches,
            sand_surface: make!(SAND_SURFACE_TOPIC, Durability::Volatile),
        };
        let urdf =
            match &scene.config.robot {
                None => None,
                Some(robot) => Some(std::fs::read_to_string(&robot.urdf).map_err(|cause| {
                    PublishError::Urdf {
                        path: robot.urdf.clone(),
                        cause,
                    }
                })?),
            };
        let mut publishing = Publishing {
            topics,
            bag,
            state_period_s: 1.0 / cfg.state_rate_hz,
            surface_period_s: if cfg.surface_rate_hz > 0.0 {
                1.0 / cfg.surface_rate_hz
            } else {
                f64::INFINITY
            },
            surface_cell_m: cfg
                .surface_cell_m
                .or(scene.sand().map(|s| s.dx_m))
                .unwrap_or(0.01),
            next_state_s: 0.0,
            next_surface_s: 0.0,
            urdf,
            time_offset_s: 0.0,
        };
        if let Some(bag) = publishing.bag.as_mut() {
            let t = &publishing.topics;
            bag.add_topic(&t.tf_static.name, TFMessage::TYPE, t.tf_static.durability)?;
            bag.add_topic(
                &t.robot_description.name,
                StringMsg::TYPE,
                t.robot_description.durability,
            )?;
        }
        Ok(publishing)
    }

    /// The stamp of the simulation's present moment.
    pub fn stamp(&self, sim: &Simulation) -> Time {
        Time::from_secs(self.time_offset_s + sim.time_s())
    }

    /// Sends `msg` on `topic`: to DDS (errors are reported, not fatal: a slow peer must not
    /// stop the simulation) and into the bag.
    fn emit<M: RosMessage>(
        bag: &mut Option<BagWriter>,
        topic: &Topic<M>,
        stamp: Time,
        msg: M,
    ) -> Result<(), PublishError> {
        if let Some(bag) = bag.as_mut() {
            bag.write(&topic.name, stamp.as_nanos(), &msg)?;
        }
        if let Some(publisher) = &topic.publisher {
            if let Err(e) = publisher.publish(msg) {
                eprintln!("warning: publishing {}: {e:?}", topic.name);
            }
        }
        Ok(())
    }

    /// Records a command the node received (commands are never published).
    pub fn record<M: RosMessage>(
        &mut self,
        topic: &str,
        stamp: Time,
        msg: &M,
    ) -> Result<(), PublishError> {
        if let Some(bag) = self.bag.as_mut() {
            bag.write(topic, stamp.as_nanos(), msg)?;
        }
        Ok(())
    }

    /// The latched topics: `/tf_static` and `robot_description`.
    pub fn publish_static(&mut self, sim: &Simulation) -> Result<(), PublishError> {
        let stamp = self.stamp(sim);
        let t = &self.topics;
        Self::emit(
            &mut self.bag,
            &t.tf_static,
            stamp,
            convert::tf_static(stamp),
        )?;
        if let Some(urdf) = &self.urdf {
            let msg = StringMsg { data: urdf.clone() };
            Self::emit(&mut self.bag, &t.robot_description, stamp, msg)?;
        }
        Ok(())
    }

    /// Publishes whatever is due at the simulation's present time: the state topics every
    /// state period, the sand surface every surface period.
    pub fn publish_due(&mut self, sim: &mut Simulation) -> Result<(), PublishError> {
        let now = self.time_offset_s + sim.time_s();
        if now + DUE_TOLERANCE_S >= self.next_state_s {
            self.publish_state(sim)?;
            self.next_state_s = next_due(self.next_state_s, self.state_period_s, now);
        }
        if now + DUE_TOLERANCE_S >= self.next_surface_s {
            if let Some(points) = sim.sand_surface(self.surface_cell_m) {
                let stamp = self.stamp(sim);
                let msg = convert::sand_surface(stamp, &points);
                Self::emit(&mut self.bag, &self.topics.sand_surface, stamp, msg)?;
            }
            self.next_surface_s = next_due(self.next_surface_s, self.surface_period_s, now);
        }
        Ok(())
    }

    /// `/clock` and the robot state topics.
    fn publish_state(&mut self, sim: &mut Simulation) -> Result<(), PublishError> {
        let stamp = self.stamp(sim);
        let t = &self.topics;
        Self::emit(&mut self.bag, &t.clock, stamp, convert::clock(stamp))?;
        let Some(robot) = sim.robot_state() else {
            return Ok(());
        };
        Self::emit(
            &mut self.bag,
            &t.joint_states,
            stamp,
            convert::joint_state(stamp, &robot),
        )?;
        Self::emit(
            &mut self.bag,
            &t.odom,
            stamp,
            convert::odometry(stamp, &robot),
        )?;
        Self::emit(
            &mut self.bag,
            &t.body_pose,
            stamp,
            convert::body_pose(stamp, &robot),
        )?;
        Self::emit(
            &mut self.bag,
            &t.tf,
            stamp,
            convert::tf(stamp, &sim.link_poses()),
        )?;
        if let Some(wrenches) = sim.take_terrain_wrenches() {
            if let Some(topic) = &t.body_wrench {
                Self::emit(
                    &mut self.bag,
                    topic,
                    stamp,
                    convert::link_wrench(stamp, &wrenches.body),
                )?;
            }
            for (topic, wrench) in t.leg_wrenches.iter().zip(&wrenches.legs) {
                Self::emit(
                    &mut self.bag,
                    topic,
                    stamp,
                    convert::link_wrench(stamp, wrench),
                )?;
            }
        }
        Ok(())
    }

    /// After a reset: the state topics are due at once.
    pub fn restart(&mut self, sim: &Simulation) {
        self.next_state_s = self.time_offset_s + sim.time_s();
        self.next_surface_s = self.next_state_s;
    }

    /// Finishes the bag, if recording.
    pub fn finish(&mut self) -> Result<Option<BagInfo>, PublishError> {
        match self.bag.take() {
            None => Ok(None),
            Some(bag) => Ok(Some(bag.finish()?)),
        }
    }

    /// Where the bag is being written, if recording.
    pub fn bag_dir(&self) -> Option<&Path> {
        self.bag.as_ref().map(BagWriter::dir)
    }
}

/// The next due time after `now`, on the grid `due + k * period`.
fn next_due(due: f64, period: f64, now: f64) -> f64 {
    if !period.is_finite() {
        return f64::INFINITY;
    }
    let mut next = due + period;
    if next <= now + DUE_TOLERANCE_S {
        next = due + ((now - due) / period).floor() * period + period;
    }
    next
}

/// Records `sandstep run` into a bag: an [`Observer`] publishing to the bag only.
impl Observer for Publishing {
    fn observe(&mut self, sim: &mut Simulation) -> Result<(), crate::scene::ObserverError> {
        if sim.time_s() == 0.0 {
            self.publish_static(sim)?;
        }
        Ok(self.publish_due(sim)?)
    }
}

/// `bags/<scene>-<YYYYmmdd-HHMMSS>` under `parent`, with `-2`, `-3`, ... if taken.
pub fn default_bag_dir(parent: &Path, scene_name: &str) -> PathBuf {
    let stamp = chrono::Local::now().format("%Y%m%d-%H%M%S");
    let base = parent.join(format!("{scene_name}-{stamp}"));
    let mut dir = base.clone();
    let mut n = 2;
    while dir.exists() {
        dir = PathBuf::from(format!("{}-{n}", base.display()));
        n += 1;
    }
    dir
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_resolve_in_the_namespace() {
        assert_eq!(resolve("/", "joint_states"), "/joint_states");
        assert_eq!(resolve("/robot1", "sand/surface"), "/robot1/sand/surface");
        assert_eq!(resolve("/robot1/", "odom"), "/robot1/odom");
        assert_eq!(resolve("/robot1", "/clock"), "/clock");
    }

    #[test]
    fn due_times_stay_on_their_grid() {
        assert!((next_due(0.0, 0.01, 0.0) - 0.01).abs() < 1e-12);
        // Called late (a coarse frame): the next due time skips ahead on the grid.
        assert!((next_due(0.01, 0.01, 0.055) - 0.06).abs() < 1e-12);
        assert_eq!(next_due(0.0, f64::INFINITY, 0.0), f64::INFINITY);
    }
}
