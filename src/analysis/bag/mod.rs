//! Offline analysis of recorded bags (`sandstep analyze`): how far and how fast the body went,
//! per gait cycle, how it bobbed and tilted, how deep the legs sank into the sand, the forces
//! of the sand on each leg and the commands received.
//!
//! Reads any rosbag2 MCAP bag with the message types of [`crate::msgs`] on the topics the
//! simulator records (see `docs/analysis.md`). Times are header stamps where a topic's messages
//! carry them (else log times, shifted onto the stamps' clock), in seconds since the first body
//! pose, so bags whose log time is wall time and stamps simulated time work too.

mod cycles;
mod report;
mod sinkage;
mod tf;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Vector3};
use serde::Serialize;

use crate::bag::{BagError, BagReader, TopicInfo};
use crate::msgs::{self, MessageType, RosMessage, Time};

pub use cycles::{cycle_boundaries, mean_and_sample_std, GaitCycle};

use tf::{pose_at, pose_to_isometry, sort_samples, transform_to_isometry, TfTree, TimedPose};

/// Body odometry, pose in the odom (world) frame (`nav_msgs/msg/Odometry`).
pub const ODOM_TOPIC: &str = "/odom";
/// Body pose, the same as `/odom` (`geometry_msgs/msg/PoseStamped`).
pub const BODY_POSE_TOPIC: &str = "/body_pose";
/// Transforms (`tf2_msgs/msg/TFMessage`).
pub const TF_TOPIC: &str = "/tf";
/// Static transforms (`tf2_msgs/msg/TFMessage`).
pub const TF_STATIC_TOPIC: &str = "/tf_static";
/// Simulated time (`rosgraph_msgs/msg/Clock`).
pub const CLOCK_TOPIC: &str = "/clock";
/// Joint angles (rad, unwrapped), velocities and efforts (`sensor_msgs/msg/JointState`).
pub const JOINT_STATES_TOPIC: &str = "/joint_states";
/// The URDF text (`std_msgs/msg/String`).
pub const ROBOT_DESCRIPTION_TOPIC: &str = "/robot_description";
/// The top of the sand as xyz points in odom (`sensor_msgs/msg/PointCloud2`).
pub const SAND_SURFACE_TOPIC: &str = "/sand/surface";
/// Prefix of the per-leg sand wrench topics, followed by the leg link name
/// (`geometry_msgs/msg/WrenchStamped`).
pub const LEG_WRENCHES_PREFIX: &str = "/leg_wrenches/";
/// The terrain's wrench on the body (`geometry_msgs/WrenchStamped`).
pub const BODY_WRENCH_TOPIC: &str = "/body_wrench";
/// Gait frequency command (Hz, sign = direction; `std_msgs/msg/Float64`).
pub const GAIT_FREQUENCY_TOPIC: &str = "/gait/frequency";
/// Body velocity command (`geometry_msgs/msg/Twist`).
pub const CMD_VEL_TOPIC: &str = "/cmd_vel";
/// Per-joint velocity commands (rad/s; `std_msgs/msg/Float64MultiArray`).
pub const LEG_VELOCITY_COMMANDS_TOPIC: &str = "/leg_velocity_controller/commands";

/// The body frame whose pose is analysed.
pub const BODY_FRAME: &str = "base_link";
/// Window (s) of the smoothed speed over time: short enough to show the speed changing within
/// a gait cycle (the per-cycle speeds give the cycle means).
pub const SPEED_WINDOW_S: f64 = 0.1;

const NANOS_PER_SECOND: f64 = 1e9;

/// The topics the analysis reads and the type each must have.
fn expected_type(topic: &str) -> Option<&'static MessageType> {
    Some(match topic {
        ODOM_TOPIC => &msgs::ODOMETRY,
        BODY_POSE_TOPIC => &msgs::POSE_STAMPED,
        TF_TOPIC | TF_STATIC_TOPIC => &msgs::TF_MESSAGE,
        CLOCK_TOPIC => &msgs::CLOCK,
        JOINT_STATES_TOPIC => &msgs::JOINT_STATE,
        ROBOT_DESCRIPTION_TOPIC => &msgs::STRING,
        SAND_SURFACE_TOPIC => &msgs::POINT_CLOUD2,
        GAIT_FREQUENCY_TOPIC => &msgs::FLOAT64,
        CMD_VEL_TOPIC => &msgs::TWIST,
        LEG_VELOCITY_COMMANDS_TOPIC => &msgs::FLOAT64_MULTI_ARRAY,
        BODY_WRENCH_TOPIC => &msgs::WRENCH_STAMPED,
        _ if topic.starts_with(LEG_WRENCHES_PREFIX) => &msgs::WRENCH_STAMPED,
        _ => return None,
    })
}

/// Why a bag could not be analysed.
#[derive(thiserror::Error, Debug)]
pub enum AnalysisError {
    /// The bag could not be read. Its message already names the cause, so it is not also
    /// given as the error's source (which `{:#}` would print a second time).
    #[error("{0}")]
    Bag(BagError),
    #[error("{}: topic {topic} has type {found}, but {topic} must be {expected}", path.display())]
    WrongType {
        path: PathBuf,
        topic: String,
        found: String,
        expected: String,
    },
    #[error(
        "{}: no body pose to analyse: needs {ODOM_TOPIC} (nav_msgs/msg/Odometry), \
         {BODY_POSE_TOPIC} (geometry_msgs/msg/PoseStamped) or {TF_TOPIC} with a transform of \
         {BODY_FRAME}; the bag has {}",
        path.display(),
        if topics.is_empty() { "no topics".to_string() } else { topics.join(", ") }
    )]
    NoPose {
        path: PathBuf,
        /// `name (type, count)` of each topic in the bag.
        topics: Vec<String>,
    },
    #[error(
        "{}: the analysis cannot start at {start_s} s: the body poses cover 0 to {end_s} s",
        path.display()
    )]
    Window {
        path: PathBuf,
        start_s: f64,
        end_s: f64,
    },
}

/// Which part of a bag to analyse.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct AnalysisOptions {
    /// Start of the analysed window (s since the first body pose; default 0, the whole bag).
    /// Every number of the summary (distance, speeds, gait cycles, heights, tilt, sinkage,
    /// leg forces) covers the time from here to the last body pose; only cycles that start
    /// here or later count. The series behind the plots cover the whole bag, except `cycles`,
    /// which are the counted ones. Commands and topics always cover the whole bag.
    pub start_s: f64,
    /// Count at most this many complete gait cycles, the first ones of the window
    /// (default: all).
    pub max_cycles: Option<usize>,
}

impl From<BagError> for AnalysisError {
    fn from(e: BagError) -> Self {
        Self::Bag(e)
    }
}

/// One topic of the bag.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TopicSummary {
    pub name: String,
    /// Full type name, e.g. `sensor_msgs/msg/JointState`.
    #[serde(rename = "type")]
    pub type_name: String,
    /// Messages in the bag.
    pub count: u64,
}

impl From<&TopicInfo> for TopicSummary {
    fn from(t: &TopicInfo) -> Self {
        Self {
            name: t.name.clone(),
            type_name: t.type_name.clone(),
            count: t.message_count,
        }
    }
}

/// The force of the sand on one link: a leg, from its `/leg_wrenches/<leg>` topic, or the body,
/// from `/body_wrench`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LinkForceSummary {
    /// The wrench topic.
    pub topic: String,
    /// Wrench messages.
    pub samples: usize,
    /// Mean of |F| over the messages (N).
    pub mean_force_n: f64,
    /// Largest |F| (N).
    pub peak_force_n: f64,
    /// Mean of the force's vertical (odom z, up positive) component (N); `None` when the
    /// link's orientation cannot be found from `/tf` and the body pose.
    pub mean_vertical_force_n: Option<f64>,
}

/// A command topic: how many commands and the first and last one.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CommandSummary {
    #[serde(rename = "type")]
    pub type_name: String,
    pub count: usize,
    /// First command: a number (`Float64`), an array (`Float64MultiArray` data) or an object
    /// with `linear` and `angular` vectors (`Twist`); `null` without messages.
    pub first: serde_json::Value,
    /// Last command, like `first`.
    pub last: serde_json::Value,
}

/// What `sandstep analyze` reports (documented with units in `docs/analysis.md`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BagSummary {
    /// The bag directory or MCAP file analysed.
    pub bag: String,
    /// Start of the analysed window (s since the first body pose; 0 = the whole bag).
    pub start_s: f64,
    /// Topic the body pose came from (`/odom`, `/body_pose`, another Odometry topic or `/tf`).
    pub pose_source: String,
    /// Time from the first to the last body pose (s).
    pub duration_s: f64,
    /// Body displacement along x (m).
    pub distance_m: f64,
    /// `distance_m / duration_s` (m/s); `None` for a single pose.
    pub mean_speed_m_s: Option<f64>,
    /// Δx/Δt over each complete gait cycle (m/s), in order.
    pub speed_per_cycle_m_s: Vec<f64>,
    /// Mean of `speed_per_cycle_m_s` (m/s); `None` without cycles.
    pub speed_per_cycle_mean_m_s: Option<f64>,
    /// Population standard deviation of `speed_per_cycle_m_s` (m/s); `None` without cycles.
    pub speed_per_cycle_std_m_s: Option<f64>,
    /// Complete gait cycles; `None` without `/joint_states`.
    pub gait_cycles: Option<usize>,
    /// The joint whose turns mark the cycles (the first joint of `/joint_states`).
    pub gait_joint: Option<String>,
    /// Body displacement along y (m).
    pub lateral_drift_m: f64,
    /// Mean body height z (m).
    pub body_height_mean_m: f64,
    /// Lowest body height z (m).
    pub body_height_min_m: f64,
    /// Largest angle between the body z axis and the vertical (degrees).
    pub max_tilt_deg: f64,
    /// Sand surface level: median z of the first `/sand/surface` cloud (m).
    pub sand_level_m: Option<f64>,
    /// Mean over time of the depth of the deepest leg point below the sand level (m, 0 when
    /// every leg is above it).
    pub sinkage_mean_m: Option<f64>,
    /// Largest such depth (m).
    pub sinkage_max_m: Option<f64>,
    /// Sand force on each leg, by leg link name.
    pub leg_forces: BTreeMap<String, LinkForceSummary>,
    /// Sand force on the body (its belly and sides); `None` without `/body_wrench`. With the
    /// legs' it carries the robot's weight on average.
    pub body_force: Option<LinkForceSummary>,
    /// Commands received, by topic.
    pub commands: BTreeMap<String, CommandSummary>,
    /// Every topic of the bag, sorted by name.
    pub topics: Vec<TopicSummary>,
    /// Plot files written (filled by `sandstep analyze --plots`).
    pub plots: Vec<String>,
    /// What was left out and why (missing optional inputs, unreadable URDF, ...).
    pub notes: Vec<String>,
}

/// A named time series `(t s, value)`.
#[derive(Clone, Debug, PartialEq)]
pub struct NamedSeries {
    pub name: String,
    pub points: Vec<(f64, f64)>,
}

/// The time series behind the summary, for plots. Times are s since the first body pose.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BagSeries {
    /// Body position `[t s, x m, y m, z m]`.
    pub body_position: Vec<[f64; 4]>,
    /// Speed along x (m/s) over a window of `speed_window_s` centred on each pose time.
    pub speed: Vec<(f64, f64)>,
    /// Window of `speed` (s): [`SPEED_WINDOW_S`].
    pub speed_window_s: f64,
    /// The complete gait cycles with their speeds.
    pub cycles: Vec<GaitCycle>,
    /// Unwrapped angle (rad) of each joint of `/joint_states`.
    pub joint_angles: Vec<NamedSeries>,
    /// |F| (N) on each leg.
    pub leg_forces: Vec<NamedSeries>,
}

/// The summary of a bag and the series it was computed from.
#[derive(Clone, Debug, PartialEq)]
pub struct BagAnalysis {
    pub summary: BagSummary,
    pub series: BagSeries,
}

/// Converts message times to seconds since the first body pose.
///
/// A topic whose messages carry header stamps (any stamp not zero) is timed by its stamps; a
/// topic without stamps by its log times, moved onto the stamps' clock by the typical
/// difference of log time and stamp of the body poses.
struct TimeBase {
    /// Median log time minus header stamp of the body poses (ns).
    log_minus_stamp_ns: i128,
    /// The analysis origin on the stamps' clock (ns).
    origin_ns: i128,
}

/// How one topic is timed.
#[derive(Clone, Copy)]
struct TopicClock<'a> {
    base: &'a TimeBase,
    /// By header stamps (else by log times).
    stamped: bool,
}

impl TopicClock<'_> {
    /// Seconds since the origin of a message with this header stamp and log time (ns).
    fn seconds(&self, stamp: &Time, log_ns: u64) -> f64 {
        (self.base.nanos(self.stamped, stamp, log_ns) - self.base.origin_ns) as f64
            / NANOS_PER_SECOND
    }
}

impl TimeBase {
    /// From the (header stamp, log time ns) of the body poses.
    fn new(pose_times: &[(Time, u64)]) -> Self {
        let stamped = any_stamp(pose_times.iter().map(|(stamp, _)| stamp));
        let mut offsets: Vec<i128> = pose_times
            .iter()
            .filter(|_| stamped)
            .map(|(stamp, log)| *log as i128 - stamp.as_nanos() as i128)
            .collect();
        offsets.sort_unstable();
        let mut base = Self {
            log_minus_stamp_ns: offsets.get(offsets.len() / 2).copied().unwrap_or(0),
            origin_ns: 0,
        };
        base.origin_ns = pose_times
            .iter()
            .map(|(stamp, log)| base.nanos(stamped, stamp, *log))
            .min()
            .unwrap_or(0);
        base
    }

    /// The clock of a topic whose messages have these stamps.
    fn clock<'s>(&self, stamps: impl IntoIterator<Item = &'s Time>) -> TopicClock<'_> {
        TopicClock {
            base: self,
            stamped: any_stamp(stamps),
        }
    }

    /// A message's time on the stamps' clock (ns).
    fn nanos(&self, stamped: bool, stamp: &Time, log_ns: u64) -> i128 {
        if stamped {
            stamp.as_nanos() as i128
        } else {
            log_ns as i128 - self.log_minus_stamp_ns
        }
    }
}

/// Whether any of the header stamps was filled in (not all zeros).
fn any_stamp<'s>(stamps: impl IntoIterator<Item = &'s Time>) -> bool {
    stamps.into_iter().any(|s| s.sec != 0 || s.nanosec != 0)
}

/// Every topic the analysis reads must have its type.
fn check_types(reader: &BagReader) -> Result<(), AnalysisError> {
    for topic in reader.topics() {
        if let Some(expected) = expected_type(&topic.name) {
            let expected = expected.type_name();
            if topic.type_name != expected {
                return Err(AnalysisError::WrongType {
                    path: reader.path().to_path_buf(),
                    topic: topic.name.clone(),
                    found: if topic.type_name.is_empty() {
                        "(no schema)".into()
                    } else {
                        topic.type_name.clone()
                    },
                    expected,
                });
            }
        }
    }
    Ok(())
}

/// The messages of `topic`, none if the bag lacks it.
fn read_optional<M: RosMessage>(
    reader: &BagReader,
    topic: &str,
) -> Result<Vec<(u64, M)>, AnalysisError> {
    if reader.topics().iter().any(|t| t.name == topic) {
        Ok(reader.read(topic)?)
    } else {
        Ok(Vec::new())
    }
}

/// Body poses as read, before times are converted.
struct RawPoses {
    /// Topic they came from.
    source: String,
    /// Frame the poses are in (`odom`).
    world_frame: String,
    /// Frame whose pose they are (`base_link`).
    body_frame: String,
    /// (header stamp, log time ns, pose); empty for poses taken from `/tf`.
    samples: Vec<(Time, u64, Isometry3<f64>)>,
}

/// The body poses from `/odom`, `/body_pose` or the only other Odometry topic; `None` if none
/// of them has messages (then `/tf` is tried).
fn read_pose_topics(reader: &BagReader) -> Result<Option<RawPoses>, AnalysisError> {
    let odometry_topic = |topic: &str| -> Result<Option<RawPoses>, AnalysisError> {
        let msgs = read_optional::<msgs::Odometry>(reader, topic)?;
        let Some((_, first)) = msgs.first() else {
            return Ok(None);
        };
        Ok(Some(RawPoses {
            source: topic.to_string(),
            world_frame: tf::frame_name(&first.header.frame_id).to_string(),
            body_frame: non_empty_or(tf::frame_name(&first.child_frame_id), BODY_FRAME),
            samples: msgs
                .iter()
                .map(|(log, m)| (m.header.stamp, *log, pose_to_isometry(&m.pose.pose)))
                .collect(),
        }))
    };
    if let Some(poses) = odometry_topic(ODOM_TOPIC)? {
        return Ok(Some(poses));
    }
    let body = read_optional::<msgs::PoseStamped>(reader, BODY_POSE_TOPIC)?;
    if let Some((_, first)) = body.first() {
        return Ok(Some(RawPoses {
            source: BODY_POSE_TOPIC.into(),
            world_frame: tf::frame_name(&first.header.frame_id).to_string(),
            body_frame: BODY_FRAME.into(),
            samples: body
                .iter()
                .map(|(log, m)| (m.header.stamp, *log, pose_to_isometry(&m.pose)))
                .collect(),
        }));
    }
    let others: Vec<String> = reader
        .topics_of_type(&msgs::ODOMETRY)
        .into_iter()
        .filter(|t| t != ODOM_TOPIC)
        .collect();
    if let [only] = others.as_slice() {
        return odometry_topic(only);
    }
    Ok(None)
}

fn non_empty_or(name: &str, default: &str) -> String {
    if name.is_empty() { default } else { name }.to_string()
}

/// Analyses the whole bag directory or MCAP file at `path`.
pub fn analyze_bag(path: &Path) -> Result<BagAnalysis, AnalysisError> {
    analyze_bag_with(path, &AnalysisOptions::default())
}

/// Analyses the bag directory or MCAP file at `path` from `opts.start_s` on.
pub fn analyze_bag_with(path: &Path, opts: &AnalysisOptions) -> Result<BagAnalysis, AnalysisError> {
    let reader = BagReader::open(path)?;
    check_types(&reader)?;
    let mut notes: Vec<String> = reader
        .warnings()
        .iter()
        .map(|w| format!("warning: {w}"))
        .collect();

    // Body poses and the time base.
    let tf_msgs = read_optional::<msgs::TFMessage>(&reader, TF_TOPIC)?;
    let tf_static_msgs = read_optional::<msgs::TFMessage>(&reader, TF_STATIC_TOPIC)?;
    let pose_topics = read_pose_topics(&reader)?;
    let pose_times: Vec<(Time, u64)> = match &pose_topics {
        Some(raw) => raw.samples.iter().map(|(s, l, _)| (*s, *l)).collect(),
        None => tf_msgs
            .iter()
            .flat_map(|(log, m)| {
                m.transforms
                    .iter()
                    .filter(|t| tf::frame_name(&t.child_frame_id) == BODY_FRAME)
                    .map(|t| (t.header.stamp, *log))
            })
            .collect(),
    };
    if pose_times.is_empty() {
        return Err(AnalysisError::NoPose {
            path: path.to_path_buf(),
            topics: reader
                .topics()
                .iter()
                .map(|t| format!("{} ({}, {})", t.name, t.type_name, t.message_count))
                .collect(),
        });
    }
    let time = TimeBase::new(&pose_times);

    let mut tree = TfTree::default();
    for (msgs, is_static) in [(&tf_msgs, false), (&tf_static_msgs, true)] {
        let clock = time.clock(
            msgs.iter()
                .flat_map(|(_, m)| m.transforms.iter().map(|t| &t.header.stamp)),
        );
        for (log, m) in msgs {
            for t in &m.transforms {
                let at = clock.seconds(&t.header.stamp, *log);
                let pose = transform_to_isometry(&t.transform);
                tree.insert(&t.header.frame_id, &t.child_frame_id, at, pose, is_static);
            }
        }
    }
    tree.finish();

    let (source, world_frame, body_frame, mut pose) = match pose_topics {
        Some(raw) => {
            let clock = time.clock(raw.samples.iter().map(|(stamp, ..)| stamp));
            let pose: Vec<TimedPose> = raw
                .samples
                .iter()
                .map(|(stamp, log, p)| (clock.seconds(stamp, *log), *p))
                .collect();
            (raw.source, raw.world_frame, raw.body_frame, pose)
        }
        None => {
            // The body in the root of its tf tree, at each of its own samples.
            let mut root = BODY_FRAME.to_string();
            while let Some(parent) = tree.parent(&root) {
                root = parent.to_string();
            }
            let times: Vec<f64> = tree
                .samples(BODY_FRAME)
                .unwrap_or_default()
                .iter()
                .map(|(t, _)| *t)
                .collect();
            let pose = times
                .iter()
                .filter_map(|t| Some((*t, tree.lookup(BODY_FRAME, &root, *t)?)))
                .collect();
            (TF_TOPIC.to_string(), root, BODY_FRAME.to_string(), pose)
        }
    };
    sort_samples(&mut pose);
    let body = BodyTrack {
        pose,
        tree,
        world_frame,
        body_frame,
    };

    let start_s = opts.start_s;
    let window = pose_window(&body.pose, start_s).ok_or_else(|| AnalysisError::Window {
        path: path.to_path_buf(),
        start_s,
        end_s: body.pose[body.pose.len() - 1].0,
    })?;
    let mut summary = pose_summary(path, &source, &window);
    summary.start_s = start_s;
    let mut series = BagSeries {
        body_position: body
            .pose
            .iter()
            .map(|(t, p)| [*t, p.translation.x, p.translation.y, p.translation.z])
            .collect(),
        ..BagSeries::default()
    };

    // Joints and gait cycles.
    let joint_states = read_optional::<msgs::JointState>(&reader, JOINT_STATES_TOPIC)?;
    series.joint_angles = joint_angle_series(&joint_states, &time);
    if let Some(first_joint) = series.joint_angles.first() {
        let boundaries = cycle_boundaries(&first_joint.points);
        series.cycles = cycles::cycles(&boundaries, &body.pose)
            .into_iter()
            .filter(|c| c.start_s >= start_s - WINDOW_TOLERANCE_S)
            .take(opts.max_cycles.unwrap_or(usize::MAX))
            .collect();
        summary.gait_joint = Some(first_joint.name.clone());
        summary.gait_cycles = Some(series.cycles.len());
        summary.speed_per_cycle_m_s = series.cycles.iter().map(|c| c.speed_m_s).collect();
        if let Some((mean, std)) = cycles::mean_and_std(&summary.speed_per_cycle_m_s) {
            summary.speed_per_cycle_mean_m_s = Some(mean);
            summary.speed_per_cycle_std_m_s = Some(std);
        }
    } else {
        notes.push(format!("gait cycles: no {JOINT_STATES_TOPIC} messages"));
    }
    series.speed_window_s = SPEED_WINDOW_S;
    series.speed = cycles::smoothed_speed(&body.pose, SPEED_WINDOW_S);

    // Legs: forces and sinkage.
    for topic in reader.topics().iter().map(|t| &t.name) {
        let Some(leg) = topic.strip_prefix(LEG_WRENCHES_PREFIX) else {
            continue;
        };
        let wrenches = read_optional::<msgs::WrenchStamped>(&reader, topic)?;
        if let Some((force_summary, force_series)) =
            link_forces(topic, leg, &wrenches, &time, &body, start_s)
        {
            summary.leg_forces.insert(leg.to_string(), force_summary);
            series.leg_forces.push(force_series);
        }
    }
    if summary.leg_forces.is_empty() {
        notes.push(format!("leg forces: no {LEG_WRENCHES_PREFIX}* messages"));
    }
    let body_wrenches = read_optional::<msgs::WrenchStamped>(&reader, BODY_WRENCH_TOPIC)?;
    summary.body_force = link_forces(
        BODY_WRENCH_TOPIC,
        &body.body_frame,
        &body_wrenches,
        &time,
        &body,
        start_s,
    )
    .map(|(force_summary, _)| force_summary);
    if summary.body_force.is_none() && !summary.leg_forces.is_empty() {
        notes.push(format!("body force: no {BODY_WRENCH_TOPIC} messages"));
    }
    sinkage_summary(&reader, &body, start_s, &mut summary, &mut notes)?;

    summary.commands = command_summaries(&reader)?;
    summary.topics = reader.topics().iter().map(TopicSummary::from).collect();
    summary.notes = notes;
    Ok(BagAnalysis { summary, series })
}

/// The body's poses and the transform tree that places the other links.
struct BodyTrack {
    /// Body pose in the world frame, by time.
    pose: Vec<TimedPose>,
    tree: TfTree,
    /// The frame of the body poses (`odom`).
    world_frame: String,
    /// The body frame (`base_link`).
    body_frame: String,
}

impl BodyTrack {
    /// The pose of `link` in the world frame at `t`: its tf chain to the body composed with
    /// the body pose, or its tf chain to the world frame; `None` outside the body poses' time
    /// range or if tf does not connect it.
    fn link_pose(&self, link: &str, t: f64) -> Option<Isometry3<f64>> {
        if let Some(in_body) = self.tree.lookup(link, &self.body_frame, t) {
            return Some(pose_at(&self.pose, t)? * in_body);
        }
        if self.world_frame.is_empty() {
            return None;
        }
        pose_at(&self.pose, t)?;
        self.tree.lookup(link, &self.world_frame, t)
    }
}

/// Times within this much (s) before the window's start count as in it.
const WINDOW_TOLERANCE_S: f64 = 1e-9;

/// The body poses from `start_s` on, beginning with the pose interpolated at `start_s`;
/// `None` if `start_s` lies after the last pose (or is not finite). All poses for a start at
/// or before the first.
fn pose_window(pose: &[TimedPose], start_s: f64) -> Option<Vec<TimedPose>> {
    let (first, last) = (pose[0].0, pose[pose.len() - 1].0);
    if !start_s.is_finite() || start_s > last + WINDOW_TOLERANCE_S {
        return None;
    }
    if start_s <= first {
        return Some(pose.to_vec());
    }
    let start = (start_s, pose_at(pose, start_s.min(last))?);
    Some(
        std::iter::once(start)
            .chain(
                pose.iter()
                    .copied()
                    .filter(|(t, _)| *t > start_s + WINDOW_TOLERANCE_S),
            )
            .collect(),
    )
}

/// The pose-only part of the summary; everything else empty.
fn pose_summary(path: &Path, source: &str, pose: &[TimedPose]) -> BagSummary {
    let (first, last) = (pose[0], pose[pose.len() - 1]);
    let duration_s = last.0 - first.0;
    let displacement = last.1.translation.vector - first.1.translation.vector;
    let heights: Vec<f64> = pose.iter().map(|(_, p)| p.translation.z).collect();
    let max_tilt_deg = pose
        .iter()
        .map(|(_, p)| {
            let body_up = p.rotation * Vector3::z();
            libm::acos(body_up.z.clamp(-1.0, 1.0)).to_degrees()
        })
        .fold(0.0, f64::max);
    BagSummary {
        bag: path.display().to_string(),
        start_s: 0.0,
        pose_source: source.to_string(),
        duration_s,
        distance_m: displacement.x,
        mean_speed_m_s: (duration_s > 0.0).then(|| displacement.x / duration_s),
        speed_per_cycle_m_s: Vec::new(),
        speed_per_cycle_mean_m_s: None,
        speed_per_cycle_std_m_s: None,
        gait_cycles: None,
        gait_joint: None,
        lateral_drift_m: displacement.y,
        body_height_mean_m: heights.iter().sum::<f64>() / heights.len() as f64,
        body_height_min_m: heights.iter().copied().fold(f64::INFINITY, f64::min),
        max_tilt_deg,
        sand_level_m: None,
        sinkage_mean_m: None,
        sinkage_max_m: None,
        leg_forces: BTreeMap::new(),
        body_force: None,
        commands: BTreeMap::new(),
        topics: Vec::new(),
        plots: Vec::new(),
        notes: Vec::new(),
    }
}

/// Each joint's position over time, joints in the order of their first appearance.
fn joint_angle_series(
    joint_states: &[(u64, msgs::JointState)],
    time: &TimeBase,
) -> Vec<NamedSeries> {
    let mut series: Vec<NamedSeries> = Vec::new();
    let clock = time.clock(joint_states.iter().map(|(_, m)| &m.header.stamp));
    for (log, m) in joint_states {
        let t = clock.seconds(&m.header.stamp, *log);
        for (name, position) in m.name.iter().zip(&m.position) {
            let index = match series.iter().position(|s| &s.name == name) {
                Some(i) => i,
                None => {
                    series.push(NamedSeries {
                        name: name.clone(),
                        points: Vec::new(),
                    });
                    series.len() - 1
                }
            };
            series[index].points.push((t, *position));
        }
    }
    for s in &mut series {
        s.points.sort_by(|a, b| a.0.total_cmp(&b.0));
    }
    series
}

/// Force statistics from `start_s` on and the whole |F| series of one link (a leg, the body);
/// `None` without messages in the window. `link` is the frame of messages that name none.
fn link_forces(
    topic: &str,
    link: &str,
    wrenches: &[(u64, msgs::WrenchStamped)],
    time: &TimeBase,
    body: &BodyTrack,
    start_s: f64,
) -> Option<(LinkForceSummary, NamedSeries)> {
    let mut points = Vec::with_capacity(wrenches.len());
    let mut magnitudes = Vec::with_capacity(wrenches.len());
    let mut vertical = Vec::new();
    let clock = time.clock(wrenches.iter().map(|(_, m)| &m.header.stamp));
    for (log, m) in wrenches {
        let t = clock.seconds(&m.header.stamp, *log);
        let f = &m.wrench.force;
        let force = Vector3::new(f.x, f.y, f.z);
        points.push((t, force.norm()));
        if t < start_s - WINDOW_TOLERANCE_S {
            continue;
        }
        magnitudes.push(force.norm());
        let frame = non_empty_or(tf::frame_name(&m.header.frame_id), link);
        if let Some(link_pose) = body.link_pose(&frame, t) {
            vertical.push((link_pose.rotation * force).z);
        }
    }
    if magnitudes.is_empty() {
        return None;
    }
    let summary = LinkForceSummary {
        topic: topic.to_string(),
        samples: magnitudes.len(),
        mean_force_n: magnitudes.iter().sum::<f64>() / magnitudes.len() as f64,
        peak_force_n: magnitudes.iter().copied().fold(0.0, f64::max),
        mean_vertical_force_n: (!vertical.is_empty())
            .then(|| vertical.iter().sum::<f64>() / vertical.len() as f64),
    };
    points.sort_by(|a, b| a.0.total_cmp(&b.0));
    Some((
        summary,
        NamedSeries {
            name: link.to_string(),
            points,
        },
    ))
}

/// Fills the sand level and the sinkage of the legs, or notes why not.
fn sinkage_summary(
    reader: &BagReader,
    body: &BodyTrack,
    start_s: f64,
    summary: &mut BagSummary,
    notes: &mut Vec<String>,
) -> Result<(), AnalysisError> {
    let clouds = read_optional::<msgs::PointCloud2>(reader, SAND_SURFACE_TOPIC)?;
    let Some(level) = clouds
        .iter()
        .find_map(|(_, c)| c.points().and_then(|p| sinkage::surface_level(&p)))
    else {
        notes.push(format!(
            "sinkage: no {SAND_SURFACE_TOPIC} cloud with xyz points"
        ));
        return Ok(());
    };
    summary.sand_level_m = Some(level);
    let descriptions = read_optional::<msgs::StringMsg>(reader, ROBOT_DESCRIPTION_TOPIC)?;
    let Some((_, urdf)) = descriptions.last() else {
        notes.push(format!("sinkage: no {ROBOT_DESCRIPTION_TOPIC} (URDF)"));
        return Ok(());
    };
    let legs = match sinkage::moving_link_geometry(&urdf.data) {
        Ok((legs, urdf_notes)) => {
            notes.extend(urdf_notes);
            legs
        }
        Err(e) => {
            notes.push(format!(
                "sinkage: {ROBOT_DESCRIPTION_TOPIC} is not a readable URDF: {e}"
            ));
            return Ok(());
        }
    };
    let legs: Vec<_> = legs
        .into_iter()
        .filter(|leg| body.link_pose(&leg.link, body.pose[0].0).is_some())
        .collect();
    if legs.is_empty() {
        notes.push("sinkage: no leg link with collision geometry is placed by /tf".into());
        return Ok(());
    }
    // Sample at the times of the first leg that moves in tf, else at the body poses.
    let times: Vec<f64> = legs
        .iter()
        .filter_map(|leg| body.tree.samples(&leg.link))
        .find(|s| s.len() > 1)
        .unwrap_or(&body.pose)
        .iter()
        .map(|(t, _)| *t)
        .filter(|t| *t >= start_s - WINDOW_TOLERANCE_S)
        .collect();
    let depths: Vec<f64> = times
        .iter()
        .filter_map(|t| {
            legs.iter()
                .filter_map(|leg| {
                    let pose = body.link_pose(&leg.link, *t)?;
                    sinkage::link_lowest_z(&pose, leg)
                })
                .min_by(f64::total_cmp)
                .map(|lowest| (level - lowest).max(0.0))
        })
        .collect();
    if depths.is_empty() {
        notes.push("sinkage: the legs' tf samples lie outside the body poses".into());
        return Ok(());
    }
    summary.sinkage_mean_m = Some(depths.iter().sum::<f64>() / depths.len() as f64);
    summary.sinkage_max_m = Some(depths.iter().copied().fold(0.0, f64::max));
    Ok(())
}

/// Count and first/last command of each command topic present.
fn command_summaries(
    reader: &BagReader,
) -> Result<BTreeMap<String, CommandSummary>, AnalysisError> {
    fn summarise<M: RosMessage>(
        reader: &BagReader,
        topic: &str,
        value: impl Fn(&M) -> serde_json::Value,
    ) -> Result<Option<CommandSummary>, AnalysisError> {
        if !reader.topics().iter().any(|t| t.name == topic) {
            return Ok(None);
        }
        let msgs = reader.read::<M>(topic)?;
        let pick = |m: Option<&(u64, M)>| m.map_or(serde_json::Value::Null, |(_, m)| value(m));
        Ok(Some(CommandSummary {
            type_name: M::TYPE.type_name(),
            count: msgs.len(),
            first: pick(msgs.first()),
            last: pick(msgs.last()),
        }))
    }
    let mut commands = BTreeMap::new();
    let entries = [
        (
            GAIT_FREQUENCY_TOPIC,
            summarise::<msgs::Float64>(reader, GAIT_FREQUENCY_TOPIC, |m| m.data.into())?,
        ),
        (
            CMD_VEL_TOPIC,
            summarise::<msgs::Twist>(reader, CMD_VEL_TOPIC, |m| {
                serde_json::to_value(m).unwrap_or_default()
            })?,
        ),
        (
            LEG_VELOCITY_COMMANDS_TOPIC,
            summarise::<msgs::Float64MultiArray>(reader, LEG_VELOCITY_COMMANDS_TOPIC, |m| {
                m.data.clone().into()
            })?,
        ),
    ];
    for (topic, summary) in entries {
        if let Some(summary) = summary {
            commands.insert(topic.to_string(), summary);
        }
    }
    Ok(commands)
}
