//! `metadata.yaml` of a rosbag2 bag and the QoS profiles it and the MCAP channels carry.
//!
//! The layout follows rosbag2 Jazzy (`rosbag2_storage/include/rosbag2_storage/yaml.hpp`,
//! `bag_metadata.hpp` and `src/rosbag2_storage/qos.cpp` on the `jazzy` branch): metadata version 9,
//! where `offered_qos_profiles` is a YAML list of profiles with policies as lower-case words in
//! `metadata.yaml`, and the same list dumped as a YAML string in the MCAP channel metadata.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

/// File name of the bag metadata inside a bag directory.
pub const METADATA_FILE_NAME: &str = "metadata.yaml";
/// `rosbag2_bagfile_information.version` that rosbag2 Jazzy writes (`BagMetadata::version`).
pub const ROSBAG2_METADATA_VERSION: u32 = 9;
/// The storage plugin of the files.
pub(crate) const STORAGE_IDENTIFIER: &str = "mcap";
/// The message serialisation of every topic.
pub(crate) const SERIALIZATION_FORMAT: &str = "cdr";
/// The ROS distribution whose bag layout this is.
pub(crate) const ROS_DISTRO: &str = "jazzy";
/// History depth of the offered QoS (messages; rclcpp's default `KeepLast(10)`).
const QOS_HISTORY_DEPTH: u32 = 10;
/// `RMW_DURATION_INFINITE` (`{sec: INT64_MAX / 1e9, nsec: INT64_MAX % 1e9}`): what a
/// publisher with no deadline, lifespan or liveliness lease offers and rosbag2 records.
const RMW_DURATION_INFINITE: QosDuration = QosDuration {
    sec: 9_223_372_036,
    nsec: 854_775_807,
};

/// Durability of the QoS a topic is offered with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Durability {
    /// Late subscribers get only new messages.
    Volatile,
    /// The publisher keeps its last messages for late subscribers (`/tf_static`,
    /// `/robot_description`); `ros2 bag play` republishes them latched.
    TransientLocal,
}

impl Durability {
    /// The policy word rosbag2 writes (`rmw_qos_durability_policy_to_str`).
    fn policy(self) -> &'static str {
        match self {
            Durability::Volatile => "volatile",
            Durability::TransientLocal => "transient_local",
        }
    }

    /// The offered QoS profiles of a topic with this durability: one reliable keep-last
    /// publisher.
    pub(crate) fn offered_qos_profiles(self) -> Vec<QosProfile> {
        vec![QosProfile {
            history: "keep_last".into(),
            depth: QOS_HISTORY_DEPTH,
            reliability: "reliable".into(),
            durability: self.policy().into(),
            deadline: RMW_DURATION_INFINITE,
            lifespan: RMW_DURATION_INFINITE,
            liveliness: "automatic".into(),
            liveliness_lease_duration: RMW_DURATION_INFINITE,
            avoid_ros_namespace_conventions: false,
        }]
    }

    /// The `offered_qos_profiles` string of an MCAP channel of this durability: the YAML list
    /// that `metadata.yaml` holds for the topic, dumped without a trailing newline as rosbag2's
    /// `serialize_rclcpp_qos_vector` does.
    pub fn offered_qos_profiles_yaml(self) -> String {
        qos_yaml(&self.offered_qos_profiles())
    }
}

/// Dumps QoS profiles as a YAML block list.
pub(crate) fn qos_yaml(profiles: &[QosProfile]) -> String {
    serde_yaml_ng::to_string(profiles)
        .expect("QoS profiles always serialise")
        .trim_end()
        .to_string()
}

/// A duration of a QoS policy.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct QosDuration {
    /// Seconds.
    pub sec: u64,
    /// Nanoseconds on top of `sec`.
    pub nsec: u64,
}

/// One offered QoS profile, fields in rosbag2's order.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq, Eq)]
pub(crate) struct QosProfile {
    pub history: String,
    /// Messages kept.
    pub depth: u32,
    pub reliability: String,
    pub durability: String,
    pub deadline: QosDuration,
    pub lifespan: QosDuration,
    pub liveliness: String,
    pub liveliness_lease_duration: QosDuration,
    pub avoid_ros_namespace_conventions: bool,
}

/// One topic as `metadata.yaml` lists it: what [`bag_metadata`] needs of it.
pub(crate) struct TopicRecord {
    pub name: String,
    /// Full type name, e.g. `sensor_msgs/msg/JointState`.
    pub type_name: String,
    pub offered_qos_profiles: Vec<QosProfile>,
    /// `RIHS01_<sha256 hex>`, or empty if not known.
    pub type_description_hash: String,
    pub message_count: u64,
}

/// The metadata of a bag of one MCAP file `file_name` holding `topics`, whose messages span
/// the log times `time_bounds` (ns; `None` for no message).
pub(crate) fn bag_metadata(
    file_name: &str,
    topics: Vec<TopicRecord>,
    time_bounds: Option<(u64, u64)>,
) -> BagMetadata {
    let (start, end) = time_bounds.unwrap_or((0, 0));
    let duration = Nanoseconds {
        nanoseconds: end - start,
    };
    let starting_time = TimePoint {
        nanoseconds_since_epoch: start,
    };
    let message_count = topics.iter().map(|t| t.message_count).sum();
    BagMetadata {
        version: ROSBAG2_METADATA_VERSION,
        storage_identifier: STORAGE_IDENTIFIER.into(),
        duration,
        starting_time,
        message_count,
        topics_with_message_count: topics
            .into_iter()
            .map(|t| TopicWithMessageCount {
                topic_metadata: TopicMetadata {
                    name: t.name,
                    type_name: t.type_name,
                    serialization_format: SERIALIZATION_FORMAT.into(),
                    offered_qos_profiles: t.offered_qos_profiles,
                    type_description_hash: t.type_description_hash,
                },
                message_count: t.message_count,
            })
            .collect(),
        compression_format: String::new(),
        compression_mode: String::new(),
        relative_file_paths: vec![file_name.to_string()],
        files: vec![FileInformation {
            path: file_name.to_string(),
            starting_time,
            duration,
            message_count,
        }],
        custom_data: None,
        ros_distro: ROS_DISTRO.into(),
    }
}

/// The whole `metadata.yaml`.
#[derive(Serialize, Debug)]
pub(crate) struct MetadataFile {
    pub rosbag2_bagfile_information: BagMetadata,
}

/// Nanoseconds, as rosbag2 nests them.
#[derive(Serialize, Debug, Clone, Copy)]
pub(crate) struct Nanoseconds {
    pub nanoseconds: u64,
}

/// A time point in nanoseconds "since the epoch" (here: since the simulation started).
#[derive(Serialize, Debug, Clone, Copy)]
pub(crate) struct TimePoint {
    pub nanoseconds_since_epoch: u64,
}

/// `rosbag2_storage::BagMetadata`, keys in the order rosbag2 writes them.
#[derive(Serialize, Debug)]
pub(crate) struct BagMetadata {
    pub version: u32,
    pub storage_identifier: String,
    pub duration: Nanoseconds,
    pub starting_time: TimePoint,
    pub message_count: u64,
    pub topics_with_message_count: Vec<TopicWithMessageCount>,
    pub compression_format: String,
    pub compression_mode: String,
    pub relative_file_paths: Vec<String>,
    pub files: Vec<FileInformation>,
    /// Written as `~` when empty, as rosbag2 does.
    pub custom_data: Option<BTreeMap<String, String>>,
    pub ros_distro: String,
}

#[derive(Serialize, Debug)]
pub(crate) struct TopicWithMessageCount {
    pub topic_metadata: TopicMetadata,
    pub message_count: u64,
}

#[derive(Serialize, Debug)]
pub(crate) struct TopicMetadata {
    pub name: String,
    /// Full type name, e.g. `sensor_msgs/msg/JointState`.
    #[serde(rename = "type")]
    pub type_name: String,
    pub serialization_format: String,
    pub offered_qos_profiles: Vec<QosProfile>,
    /// `RIHS01_<sha256 hex>`.
    pub type_description_hash: String,
}

#[derive(Serialize, Debug)]
pub(crate) struct FileInformation {
    /// Relative to the bag directory.
    pub path: String,
    pub starting_time: TimePoint,
    pub duration: Nanoseconds,
    pub message_count: u64,
}

/// What the reader needs of a `metadata.yaml` of any version (other keys are ignored).
#[derive(Deserialize, Debug)]
pub(crate) struct MetadataFileIn {
    pub rosbag2_bagfile_information: BagMetadataIn,
}

#[derive(Deserialize, Debug)]
pub(crate) struct BagMetadataIn {
    #[serde(default)]
    pub storage_identifier: String,
    pub relative_file_paths: Vec<String>,
    #[serde(default)]
    pub topics_with_message_count: Vec<TopicWithMessageCountIn>,
    #[serde(default)]
    pub compression_format: String,
    #[serde(default)]
    pub compression_mode: String,
}

#[derive(Deserialize, Debug)]
pub(crate) struct TopicWithMessageCountIn {
    pub topic_metadata: TopicMetadataIn,
    pub message_count: u64,
}

#[derive(Deserialize, Debug)]
pub(crate) struct TopicMetadataIn {
    pub name: String,
}
