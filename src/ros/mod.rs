//! The simulator as a ROS 2 node (ros2-client on RustDDS, no ROS installation needed): topics,
//! commands, services, and the bag every run records (`docs/ros.md`).
//!
//! Sees only plain simulation outputs ([`crate::scene::Simulation`]) and the message types of
//! [`crate::msgs`]; records through [`crate::bag`].

pub mod commands;
pub mod convert;
pub mod node;
pub mod publishing;
pub mod qos;
pub mod record;

pub use node::{run_node, NodeError, NodeRunOptions, NodeSummary};
pub use publishing::{default_bag_dir, Publishing};
pub use record::{record_run, RecordError, RecordedRun};

use crate::msgs::{
    Clock, Float64, Float64MultiArray, JointState, Odometry, PointCloud2, PoseStamped,
    ServiceResponse, SetBoolRequest, StringMsg, TFMessage, TriggerRequest, Twist, WrenchStamped,
};

/// ros2-client's marker for types it may publish, take, request and answer.
macro_rules! ros2_messages {
    ($($ty:ty),*) => { $(impl ros2_client::Message for $ty {})* };
}
ros2_messages!(
    Clock,
    Float64,
    Float64MultiArray,
    JointState,
    Odometry,
    PointCloud2,
    PoseStamped,
    ServiceResponse,
    SetBoolRequest,
    StringMsg,
    TFMessage,
    TriggerRequest,
    Twist,
    WrenchStamped
);
