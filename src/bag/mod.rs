//! rosbag2 bags in MCAP storage: a writer ([`BagWriter`]) and a reader ([`BagReader`]).
//!
//! A bag is a directory holding `<dirname>_0.mcap` and `metadata.yaml`, as `ros2 bag record`
//! (ROS 2 Jazzy) writes them, so that `ros2 bag info`/`play`, Foxglove, the Python `mcap` and
//! `rosbags` packages read them. Messages are CDR ([`crate::msgs::to_cdr`]); each channel carries
//! its `ros2msg` schema, its offered QoS and its RIHS01 type hash.
//!
//! Times are nanoseconds as given to [`BagWriter::write`] (the node uses simulated time since
//! the start, so "since the epoch" in `metadata.yaml` means "since the simulation started").

mod chunks;
mod metadata;
mod reader;
mod reindex;
mod type_hash;
mod writer;

#[cfg(test)]
mod tests;

use std::path::PathBuf;

pub use crate::msgs::{from_cdr, to_cdr, CdrError, MessageType, RosMessage};
pub use metadata::{Durability, METADATA_FILE_NAME, ROSBAG2_METADATA_VERSION};
pub use reader::BagReader;
pub use reindex::{reindex, Reindexed};
pub use type_hash::type_description_hash;
pub use writer::{BagInfo, BagWriter};

/// One topic of a bag: its name, full type name (`sensor_msgs/msg/JointState`) and how many
/// messages it holds.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct TopicInfo {
    pub name: String,
    pub type_name: String,
    pub message_count: u64,
}

/// Why a bag could not be written or read. Each message names the file, topic or field.
#[derive(thiserror::Error, Debug)]
pub enum BagError {
    #[error("{}: {cause}", path.display())]
    Io {
        path: PathBuf,
        /// Not `source`: the message already shows it (no repeat in error chains).
        cause: std::io::Error,
    },
    #[error("{}: bag directory exists and is not empty", path.display())]
    DirNotEmpty { path: PathBuf },
    #[error("{}: not a usable bag path ({reason})", path.display())]
    BadPath { path: PathBuf, reason: String },
    #[error("{}: not a readable MCAP file: {cause}", path.display())]
    Mcap {
        path: PathBuf,
        cause: mcap::McapError,
    },
    #[error("{}: {message}", path.display())]
    Metadata { path: PathBuf, message: String },
    #[error("{}: no .mcap file in the bag directory", path.display())]
    NoMcap { path: PathBuf },
    #[error("{}: several .mcap files and no metadata.yaml to order them: {}", path.display(), files.join(", "))]
    SeveralMcap { path: PathBuf, files: Vec<String> },
    #[error("{}: topic {topic} has type {first} in one channel and {second} in another", path.display())]
    ChannelTypeConflict {
        path: PathBuf,
        topic: String,
        first: String,
        second: String,
    },
    #[error("topic {topic} is declared as {declared}, cannot record {requested} on it")]
    TopicTypeConflict {
        topic: String,
        declared: String,
        requested: String,
    },
    #[error(
        "topic {topic} is declared with durability {declared:?}, cannot redeclare it {requested:?}"
    )]
    TopicDurabilityConflict {
        topic: String,
        declared: Durability,
        requested: Durability,
    },
    #[error("topic name {topic:?} is empty")]
    EmptyTopicName { topic: String },
    #[error("topic {topic}: encoded message is not CDR ({reason})")]
    NotCdr { topic: String, reason: String },
    #[error("topic {topic} is not in the bag {}; topics present: {}", path.display(), present.join(", "))]
    TopicAbsent {
        path: PathBuf,
        topic: String,
        present: Vec<String>,
    },
    #[error("topic {topic} in {} has type {bag_type}, expected {expected}", path.display())]
    TypeMismatch {
        path: PathBuf,
        topic: String,
        bag_type: String,
        expected: String,
    },
    #[error("topic {topic} in {} has message encoding {encoding:?}, only cdr is read", path.display())]
    Encoding {
        path: PathBuf,
        topic: String,
        encoding: String,
    },
    #[error("topic {topic} in {}: message {index} does not decode: {cause}", path.display())]
    Decode {
        path: PathBuf,
        topic: String,
        index: usize,
        cause: CdrError,
    },
}

impl BagError {
    fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            cause: source,
        }
    }

    fn mcap(path: impl Into<PathBuf>, source: mcap::McapError) -> Self {
        Self::Mcap {
            path: path.into(),
            cause: source,
        }
    }
}
