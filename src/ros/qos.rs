//! QoS profiles (`docs/ros.md`): published topics are reliable, keep-last, volatile or (for
//! latched topics) transient local; commands are read best-effort, which matches both reliable
//! and best-effort publishers.

use ros2_client::qos::{Durability as DdsDurability, History, Reliability, WhenFull};
use ros2_client::QosProfile;

use crate::bag::Durability;

/// Messages kept per topic for late or slow readers (the ROS 2 default depth).
pub const HISTORY_DEPTH: usize = 10;

/// The QoS of a published topic.
pub fn publisher(durability: Durability) -> QosProfile {
    QosProfile::publisher_default()
        .reliability(Reliability::Reliable {
            when_full: WhenFull::DEFAULT,
        })
        .history(History::KeepLast {
            depth: HISTORY_DEPTH,
        })
        .durability(match durability {
            Durability::Volatile => DdsDurability::Volatile,
            Durability::TransientLocal => DdsDurability::TransientLocal,
        })
}

/// The QoS of a command subscription.
pub fn command() -> QosProfile {
    QosProfile::subscription_default()
        .reliability(Reliability::BestEffort)
        .history(History::KeepLast {
            depth: HISTORY_DEPTH,
        })
        .durability(DdsDurability::Volatile)
}

/// The QoS of service requests and replies (as rclcpp: reliable, volatile, keep-last).
pub fn service() -> QosProfile {
    publisher(Durability::Volatile)
}
