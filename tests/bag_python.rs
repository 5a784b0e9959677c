//! Bags written by `sandstep::bag` read back by the Python tools people use on ROS 2 bags:
//! `mcap` with `mcap-ros2-support`, and `rosbags` (which reads `metadata.yaml` too). Every
//! message type of `sandstep::msgs` is written with known values on its own topic and must come
//! back field for field, with its schema, QoS and type hash.

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde_json::Value;

use sandstep::bag::{type_description_hash, BagReader, BagWriter, Durability};
use sandstep::msgs::*;

/// Nanoseconds per second.
const NS_PER_S: u64 = 1_000_000_000;
/// Time between the messages of one topic (ns): 100 Hz.
const PERIOD_NS: u64 = 10_000_000;

/// What was written on one topic.
struct ExpectedTopic {
    type_name: String,
    type_hash: String,
    durability: Durability,
    /// (log time in ns, the message as JSON).
    messages: Vec<(u64, Value)>,
}

/// Writes messages and remembers them.
struct Recorder {
    writer: BagWriter,
    expected: BTreeMap<String, ExpectedTopic>,
}

impl Recorder {
    fn record<M: RosMessage>(&mut self, topic: &str, durability: Durability, msgs: &[(u64, M)]) {
        self.writer.add_topic(topic, M::TYPE, durability).unwrap();
        for (time, msg) in msgs {
            self.writer.write(topic, *time, msg).unwrap();
        }
        self.expected.insert(
            topic.to_string(),
            ExpectedTopic {
                type_name: M::TYPE.type_name(),
                type_hash: type_description_hash(M::TYPE).unwrap(),
                durability,
                messages: msgs
                    .iter()
                    .map(|(t, m)| (*t, serde_json::to_value(m).unwrap()))
                    .collect(),
            },
        );
    }
}

/// `n` messages from `make(i)` at 1 s + i periods.
fn series<M>(n: u64, make: impl Fn(u64, Time) -> M) -> Vec<(u64, M)> {
    (0..n)
        .map(|i| {
            let t = NS_PER_S + i * PERIOD_NS;
            (t, make(i, Time::from_nanos(t)))
        })
        .collect()
}

fn transform(parent: &str, child: &str, stamp: Time, x: f64) -> TransformStamped {
    TransformStamped {
        header: Header::new(stamp, parent),
        child_frame_id: child.into(),
        transform: Transform {
            translation: [x, 0.25, -0.125].into(),
            rotation: [0.0, 0.0, 0.6, 0.8].into(),
        },
    }
}

fn pose(x: f64) -> Pose {
    Pose {
        position: [x, -1.5, 0.3].into(),
        orientation: [0.0, 0.28, 0.0, 0.96].into(),
    }
}

/// Writes a bag with every message type of `sandstep::msgs` to `dir`.
fn write_bag(dir: &Path) -> BTreeMap<String, ExpectedTopic> {
    let mut rec = Recorder {
        writer: BagWriter::create(dir).unwrap(),
        expected: BTreeMap::new(),
    };
    use Durability::{TransientLocal, Volatile};
    let joint_names: Vec<String> = ["leg_fl", "leg_ml", "leg_rl", "leg_fr", "leg_mr", "leg_rr"]
        .iter()
        .map(|leg| format!("{leg}_joint"))
        .collect();
    let cloud_points: Vec<[f32; 3]> = (0..50)
        .map(|i| {
            [
                i as f32 * 0.01,
                -(i as f32) * 0.02,
                0.05 + (i % 7) as f32 * 0.001,
            ]
        })
        .collect();

    rec.record("/clock", Volatile, &series(5, |_, t| Clock { clock: t }));
    rec.record(
        "/joint_states",
        Volatile,
        &series(4, |i, t| JointState {
            header: Header::new(t, ""),
            name: joint_names.clone(),
            position: (0..6).map(|j| j as f64 * 0.5 - i as f64 * 0.125).collect(),
            velocity: (0..6).map(|j| -(j as f64) * 0.25).collect(),
            effort: vec![1.5; 6],
        }),
    );
    rec.record(
        "/odom",
        Volatile,
        &series(3, |i, t| Odometry {
            header: Header::new(t, "odom"),
            child_frame_id: "base_link".into(),
            pose: PoseWithCovariance {
                pose: pose(0.5 + i as f64 * 0.25),
                covariance: std::array::from_fn(|k| if k % 7 == 0 { 0.01 } else { 0.0 }),
            },
            twist: TwistWithCovariance {
                twist: Twist {
                    linear: [0.2, 0.0, 0.0].into(),
                    angular: [0.0, 0.0, 0.125].into(),
                },
                covariance: std::array::from_fn(|k| k as f64),
            },
        }),
    );
    rec.record(
        "/tf",
        Volatile,
        &series(2, |i, t| TFMessage {
            transforms: vec![
                transform("odom", "base_link", t, i as f64),
                transform("base_link", "leg_fl", t, 0.5),
            ],
        }),
    );
    rec.record(
        "/tf_static",
        TransientLocal,
        &[(
            0,
            TFMessage {
                transforms: vec![transform("base_link", "imu", Time::default(), 0.0)],
            },
        )],
    );
    rec.record(
        "/robot_description",
        TransientLocal,
        &[(
            0,
            StringMsg {
                data: "<robot name=\"hexapod\"><link name=\"base_link\"/></robot>".into(),
            },
        )],
    );
    rec.record(
        "/body_pose",
        Volatile,
        &series(2, |i, t| PoseStamped {
            header: Header::new(t, "world"),
            pose: pose(i as f64),
        }),
    );
    rec.record(
        "/leg_wrenches/leg_fl",
        Volatile,
        &series(3, |i, t| WrenchStamped {
            header: Header::new(t, "leg_fl"),
            wrench: Wrench {
                force: [1.0, -2.0, 30.0 + i as f64].into(),
                torque: [0.0, 0.5, 0.0].into(),
            },
        }),
    );
    rec.record(
        "/sand/surface",
        Volatile,
        &series(1, |_, t| {
            PointCloud2::from_points(Header::new(t, "world"), &cloud_points)
        }),
    );
    rec.record(
        "/gait/frequency",
        Volatile,
        &series(2, |i, _| Float64 {
            data: 1.5 + i as f64,
        }),
    );
    rec.record(
        "/cmd_vel",
        Volatile,
        &series(2, |_, _| Twist {
            linear: [0.3, 0.0, 0.0].into(),
            angular: [0.0, 0.0, -0.25].into(),
        }),
    );
    rec.record(
        "/leg_velocity_controller/commands",
        Volatile,
        &series(2, |i, _| Float64MultiArray {
            layout: MultiArrayLayout {
                dim: vec![MultiArrayDimension {
                    label: "joints".into(),
                    size: 6,
                    stride: 6,
                }],
                data_offset: 0,
            },
            data: (0..6).map(|j| j as f64 - i as f64).collect(),
        }),
    );

    // The types the topics above only nest, each on a topic of its own.
    let stamp = Time::from_nanos(NS_PER_S + 5);
    rec.record("/types/time", Volatile, &[(1, stamp)]);
    rec.record(
        "/types/header",
        Volatile,
        &[(1, Header::new(stamp, "frame"))],
    );
    let dimension = MultiArrayDimension {
        label: "rows".into(),
        size: 3,
        stride: 9,
    };
    rec.record(
        "/types/multi_array_dimension",
        Volatile,
        &[(1, dimension.clone())],
    );
    rec.record(
        "/types/multi_array_layout",
        Volatile,
        &[(
            1,
            MultiArrayLayout {
                dim: vec![dimension],
                data_offset: 2,
            },
        )],
    );
    rec.record(
        "/types/vector3",
        Volatile,
        &[(1, Vector3::from([1.0, 2.0, 3.0]))],
    );
    rec.record(
        "/types/point",
        Volatile,
        &[(1, Point::from([-1.0, 0.5, 8.0]))],
    );
    rec.record(
        "/types/quaternion",
        Volatile,
        &[(1, Quaternion::from([0.0, 0.6, 0.0, 0.8]))],
    );
    rec.record("/types/pose", Volatile, &[(1, pose(4.0))]);
    rec.record(
        "/types/pose_with_covariance",
        Volatile,
        &[(
            1,
            PoseWithCovariance {
                pose: pose(5.0),
                covariance: std::array::from_fn(|k| -(k as f64)),
            },
        )],
    );
    rec.record(
        "/types/twist_with_covariance",
        Volatile,
        &[(
            1,
            TwistWithCovariance {
                twist: Twist::default(),
                covariance: std::array::from_fn(|k| k as f64 * 0.25),
            },
        )],
    );
    rec.record(
        "/types/transform",
        Volatile,
        &[(1, transform("a", "b", stamp, 2.0).transform)],
    );
    rec.record(
        "/types/transform_stamped",
        Volatile,
        &[(1, transform("a", "b", stamp, 3.0))],
    );
    rec.record(
        "/types/wrench",
        Volatile,
        &[(
            1,
            Wrench {
                force: [0.0, 0.0, -9.81].into(),
                torque: [0.1, 0.2, 0.3].into(),
            },
        )],
    );
    rec.record(
        "/types/point_field",
        Volatile,
        &[(
            1,
            PointField {
                name: "intensity".into(),
                offset: 12,
                datatype: POINT_FIELD_FLOAT32,
                count: 1,
            },
        )],
    );

    let Recorder { writer, expected } = rec;
    let info = writer.finish().unwrap();
    let written: u64 = expected.values().map(|t| t.messages.len() as u64).sum();
    assert_eq!(info.message_count, written);
    expected
}

/// A fresh bag directory under the target's temporary directory (kept for inspection).
fn bag_dir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("bag_python")
        .join(name);
    if dir.exists() {
        std::fs::remove_dir_all(&dir).unwrap();
    }
    dir
}

/// The `(log time, message)` pairs of a script's topic entry.
fn messages_of(topic: &Value) -> Vec<(u64, Value)> {
    topic["messages"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| (m["log_time"].as_u64().unwrap(), m["msg"].clone()))
        .collect()
}

/// The topics of a script's output, sorted.
fn topic_names(output: &Value) -> Vec<String> {
    let mut names: Vec<String> = output["topics"]
        .as_object()
        .unwrap()
        .keys()
        .cloned()
        .collect();
    names.sort();
    names
}

/// Every message type that `sandstep::msgs` defines, by full name.
fn all_message_types() -> Vec<String> {
    [
        &TIME,
        &HEADER,
        &STRING,
        &FLOAT64,
        &MULTI_ARRAY_DIMENSION,
        &MULTI_ARRAY_LAYOUT,
        &FLOAT64_MULTI_ARRAY,
        &CLOCK,
        &VECTOR3,
        &POINT,
        &QUATERNION,
        &POSE,
        &POSE_STAMPED,
        &POSE_WITH_COVARIANCE,
        &TWIST,
        &TWIST_WITH_COVARIANCE,
        &TRANSFORM,
        &TRANSFORM_STAMPED,
        &WRENCH,
        &WRENCH_STAMPED,
        &TF_MESSAGE,
        &ODOMETRY,
        &JOINT_STATE,
        &POINT_FIELD,
        &POINT_CLOUD2,
    ]
    .iter()
    .map(|t| t.type_name())
    .collect()
}

#[test]
fn python_readers_decode_every_message_type() {
    let dir = bag_dir("all_types");
    let expected = write_bag(&dir);
    let expected_names: Vec<String> = expected.keys().cloned().collect();

    let mut written_types: Vec<String> = expected.values().map(|t| t.type_name.clone()).collect();
    written_types.sort();
    written_types.dedup();
    let mut all_types = all_message_types();
    all_types.sort();
    assert_eq!(written_types, all_types, "every message type is in the bag");

    // Our own reader agrees with metadata.yaml.
    let reader = BagReader::open(&dir).unwrap();
    let counts: Vec<(String, u64)> = reader
        .topics()
        .iter()
        .map(|t| (t.name.clone(), t.message_count))
        .collect();
    assert_eq!(reader.metadata_counts().unwrap(), counts);

    // mcap + mcap-ros2-support.
    let mcap = common::run_python_json("read_bag_mcap.py", &[&dir]);
    assert_eq!(mcap["profiles"], serde_json::json!(["ros2"]));
    assert_eq!(topic_names(&mcap), expected_names);
    for (name, want) in &expected {
        let got = &mcap["topics"][name];
        assert_eq!(got["schema"], want.type_name.as_str(), "{name}");
        assert_eq!(got["schema_encoding"], "ros2msg", "{name}");
        assert_eq!(got["encoding"], "cdr", "{name}");
        assert_eq!(
            got["metadata"]["offered_qos_profiles"],
            want.durability.offered_qos_profiles_yaml().as_str(),
            "{name}"
        );
        assert_eq!(
            got["metadata"]["topic_type_hash"],
            want.type_hash.as_str(),
            "{name}"
        );
        assert_eq!(
            messages_of(got),
            want.messages,
            "{name} as mcap_ros2 decodes it"
        );
    }

    // rosbags AnyReader on the directory (metadata.yaml and the MCAP's channels must agree,
    // or it silently finds no messages; it also checks each type hash against the schema).
    let rosbags = common::run_python_json("read_bag_rosbags.py", &[&dir]);
    assert_eq!(topic_names(&rosbags), expected_names);
    let total: usize = expected.values().map(|t| t.messages.len()).sum();
    assert_eq!(rosbags["message_count"].as_u64(), Some(total as u64));
    assert_eq!(rosbags["start_time"].as_u64(), Some(0));
    for (name, want) in &expected {
        let got = &rosbags["topics"][name];
        assert_eq!(got["type"], want.type_name.as_str(), "{name}");
        assert_eq!(
            got["metadata_count"].as_u64(),
            Some(want.messages.len() as u64),
            "{name}: metadata.yaml count"
        );
        assert_eq!(
            messages_of(got),
            want.messages,
            "{name} as rosbags reads it"
        );
        assert_eq!(got["digest"], want.type_hash.as_str(), "{name}");
        assert_eq!(
            got["jazzy_digest"],
            want.type_hash.as_str(),
            "{name}: type hash of the ROS 2 Jazzy definition"
        );
        let durability = match want.durability {
            Durability::Volatile => "volatile",
            Durability::TransientLocal => "transient_local",
        };
        assert_eq!(
            got["durabilities"],
            serde_json::json!([durability]),
            "{name}"
        );
    }
}

#[test]
fn python_scripts_fail_loudly_on_a_broken_bag() {
    let dir = bag_dir("broken");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("broken_0.mcap"), b"not an mcap file").unwrap();
    for script in ["read_bag_mcap.py", "read_bag_rosbags.py"] {
        let output = std::process::Command::new(common::python())
            .arg(
                Path::new(env!("CARGO_MANIFEST_DIR"))
                    .join("tests/python")
                    .join(script),
            )
            .arg(&dir)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(!output.status.success(), "{script} accepted a broken bag");
        assert!(stderr.contains("FAILED"), "{script}: {stderr}");
    }
}
