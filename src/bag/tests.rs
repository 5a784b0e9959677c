//! Unit tests of the bag writer and reader.

use std::collections::BTreeMap;
use std::path::Path;

use super::*;
use crate::msgs::*;

/// Nanoseconds per second.
const NS_PER_S: u64 = 1_000_000_000;

fn odometry(t_ns: u64, x: f64) -> Odometry {
    Odometry {
        header: Header::new(Time::from_nanos(t_ns), "odom"),
        child_frame_id: "base_link".into(),
        pose: PoseWithCovariance {
            pose: Pose {
                position: [x, -0.25, 0.12].into(),
                orientation: [0.0, 0.0, 0.6, 0.8].into(),
            },
            covariance: std::array::from_fn(|i| i as f64 * 0.5),
        },
        twist: TwistWithCovariance {
            twist: Twist {
                linear: [0.1, 0.0, 0.0].into(),
                angular: [0.0, 0.0, -0.3].into(),
            },
            covariance: [0.0; 36],
        },
    }
}

fn joint_state(t_ns: u64) -> JointState {
    JointState {
        header: Header::new(Time::from_nanos(t_ns), ""),
        name: vec!["leg_fl_joint".into(), "leg_fr_joint".into()],
        position: vec![0.5, -1.25],
        velocity: vec![3.0, 4.0],
        effort: vec![],
    }
}

fn wrench(t_ns: u64, fz: f64) -> WrenchStamped {
    WrenchStamped {
        header: Header::new(Time::from_nanos(t_ns), "leg"),
        wrench: Wrench {
            force: [0.0, 0.0, fz].into(),
            torque: Vector3::default(),
        },
    }
}

/// Parses a bag's `metadata.yaml`.
fn metadata_yaml(dir: &Path) -> serde_yaml_ng::Value {
    let text = std::fs::read_to_string(dir.join(METADATA_FILE_NAME)).unwrap();
    serde_yaml_ng::from_str(&text).unwrap()
}

/// `metadata.yaml`'s `topic_metadata` of `topic`.
fn topic_metadata(metadata: &serde_yaml_ng::Value, topic: &str) -> serde_yaml_ng::Value {
    metadata["rosbag2_bagfile_information"]["topics_with_message_count"]
        .as_sequence()
        .unwrap()
        .iter()
        .map(|t| t["topic_metadata"].clone())
        .find(|t| t["name"].as_str() == Some(topic))
        .unwrap_or_else(|| panic!("{topic} missing from metadata.yaml"))
}

/// Channel metadata by topic, read with the mcap crate directly.
fn channel_metadata(mcap_path: &Path) -> BTreeMap<String, BTreeMap<String, String>> {
    let bytes = std::fs::read(mcap_path).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    summary
        .channels
        .values()
        .map(|c| (c.topic.clone(), c.metadata.clone()))
        .collect()
}

#[test]
fn messages_of_several_types_round_trip() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run1");
    let mut writer = BagWriter::create(&dir).unwrap();
    assert_eq!(writer.dir(), dir);
    let cloud_points = [[0.1f32, 0.2, 0.3], [-1.0, 2.5, 0.0], [4.0, 5.0, 6.0]];
    let cloud = PointCloud2::from_points(
        Header::new(Time::from_nanos(NS_PER_S), "world"),
        &cloud_points,
    );
    let tf = TFMessage {
        transforms: vec![TransformStamped {
            header: Header::new(Time::from_nanos(NS_PER_S), "odom"),
            child_frame_id: "base_link".into(),
            transform: Transform {
                translation: [1.0, 2.0, 3.0].into(),
                rotation: Quaternion::default(),
            },
        }],
    };
    // Times out of order on purpose: the reader returns log-time order.
    let times = [2 * NS_PER_S, NS_PER_S, 3 * NS_PER_S];
    for (i, &t) in times.iter().enumerate() {
        writer.write("/odom", t, &odometry(t, i as f64)).unwrap();
        writer.write("/joint_states", t, &joint_state(t)).unwrap();
        writer
            .write(
                "/clock",
                t,
                &Clock {
                    clock: Time::from_nanos(t),
                },
            )
            .unwrap();
    }
    writer.write("/sand/surface", NS_PER_S, &cloud).unwrap();
    writer.write("/tf", NS_PER_S, &tf).unwrap();
    writer
        .write("/gait/frequency", NS_PER_S, &Float64 { data: 1.5 })
        .unwrap();
    writer
        .write("/leg_wrenches/leg_fl", NS_PER_S, &wrench(NS_PER_S, 10.0))
        .unwrap();
    writer
        .write("/leg_wrenches/leg_fr", NS_PER_S, &wrench(NS_PER_S, 20.0))
        .unwrap();
    let cdr = to_cdr(&StringMsg {
        data: "<robot/>".into(),
    });
    writer
        .write_cdr("/robot_description", &STRING, 0, &cdr)
        .unwrap();
    let info = writer.finish().unwrap();

    assert_eq!(info.dir, dir);
    assert_eq!(info.mcap_path, dir.join("run1_0.mcap"));
    assert!(info.mcap_path.is_file());
    assert_eq!(info.message_count, 15);
    assert_eq!(info.start_time_ns, Some(0));
    assert_eq!(info.duration_ns, 3 * NS_PER_S);

    let reader = BagReader::open(&dir).unwrap();
    assert_eq!(reader.topics(), info.topics.as_slice());
    let names: Vec<&str> = reader.topics().iter().map(|t| t.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "/clock",
            "/gait/frequency",
            "/joint_states",
            "/leg_wrenches/leg_fl",
            "/leg_wrenches/leg_fr",
            "/odom",
            "/robot_description",
            "/sand/surface",
            "/tf"
        ]
    );
    let odom_info = &reader.topics()[5];
    assert_eq!(odom_info.type_name, "nav_msgs/msg/Odometry");
    assert_eq!(odom_info.message_count, 3);
    let metadata_counts = reader.metadata_counts().unwrap();
    let mcap_counts: Vec<(String, u64)> = reader
        .topics()
        .iter()
        .map(|t| (t.name.clone(), t.message_count))
        .collect();
    assert_eq!(metadata_counts, mcap_counts);
    assert_eq!(reader.start_time_ns(), Some(0));
    assert_eq!(reader.end_time_ns(), Some(3 * NS_PER_S));

    let odom = reader.read::<Odometry>("/odom").unwrap();
    let expected: Vec<(u64, Odometry)> =
        [(NS_PER_S, 1.0), (2 * NS_PER_S, 0.0), (3 * NS_PER_S, 2.0)]
            .iter()
            .map(|&(t, x)| (t, odometry(t, x)))
            .collect();
    assert_eq!(odom, expected);
    let joints = reader.read::<JointState>("/joint_states").unwrap();
    assert_eq!(joints[0], (NS_PER_S, joint_state(NS_PER_S)));
    let clouds = reader.read::<PointCloud2>("/sand/surface").unwrap();
    assert_eq!(clouds, vec![(NS_PER_S, cloud.clone())]);
    assert_eq!(clouds[0].1.points().unwrap(), cloud_points);
    assert_eq!(reader.read::<TFMessage>("/tf").unwrap()[0].1, tf);
    assert_eq!(
        reader.read::<Float64>("/gait/frequency").unwrap(),
        vec![(NS_PER_S, Float64 { data: 1.5 })]
    );
    assert_eq!(
        reader.read::<StringMsg>("/robot_description").unwrap()[0]
            .1
            .data,
        "<robot/>"
    );
    assert_eq!(
        reader.topics_of_type(&WRENCH_STAMPED),
        ["/leg_wrenches/leg_fl", "/leg_wrenches/leg_fr"]
    );
    let fr = reader
        .read::<WrenchStamped>("/leg_wrenches/leg_fr")
        .unwrap();
    assert_eq!(fr[0].1.wrench.force.z, 20.0);

    // The same file opened bare, and the directory without metadata.yaml.
    let bare = BagReader::open(&info.mcap_path).unwrap();
    assert_eq!(bare.topics(), reader.topics());
    assert_eq!(bare.metadata_counts(), None);
    std::fs::remove_file(dir.join(METADATA_FILE_NAME)).unwrap();
    let no_metadata = BagReader::open(&dir).unwrap();
    assert_eq!(no_metadata.read::<Odometry>("/odom").unwrap(), expected);
}

#[test]
fn metadata_yaml_has_the_jazzy_layout() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("layout");
    let mut writer = BagWriter::create(&dir).unwrap();
    writer
        .write("/gait/frequency", 5, &Float64 { data: 1.0 })
        .unwrap();
    writer
        .write("/gait/frequency", 25, &Float64 { data: 2.0 })
        .unwrap();
    writer.finish().unwrap();

    let metadata = metadata_yaml(&dir);
    let info = &metadata["rosbag2_bagfile_information"];
    let keys: Vec<&str> = info
        .as_mapping()
        .unwrap()
        .keys()
        .map(|k| k.as_str().unwrap())
        .collect();
    assert_eq!(
        keys,
        [
            "version",
            "storage_identifier",
            "duration",
            "starting_time",
            "message_count",
            "topics_with_message_count",
            "compression_format",
            "compression_mode",
            "relative_file_paths",
            "files",
            "custom_data",
            "ros_distro"
        ]
    );
    assert_eq!(info["version"].as_u64(), Some(9));
    assert_eq!(info["storage_identifier"].as_str(), Some("mcap"));
    assert_eq!(info["duration"]["nanoseconds"].as_u64(), Some(20));
    assert_eq!(
        info["starting_time"]["nanoseconds_since_epoch"].as_u64(),
        Some(5)
    );
    assert_eq!(info["message_count"].as_u64(), Some(2));
    assert_eq!(info["compression_format"].as_str(), Some(""));
    assert_eq!(info["compression_mode"].as_str(), Some(""));
    assert_eq!(
        info["relative_file_paths"][0].as_str(),
        Some("layout_0.mcap")
    );
    let file = &info["files"][0];
    assert_eq!(file["path"].as_str(), Some("layout_0.mcap"));
    assert_eq!(
        file["starting_time"]["nanoseconds_since_epoch"].as_u64(),
        Some(5)
    );
    assert_eq!(file["duration"]["nanoseconds"].as_u64(), Some(20));
    assert_eq!(file["message_count"].as_u64(), Some(2));
    assert!(info["custom_data"].is_null());
    assert_eq!(info["ros_distro"].as_str(), Some("jazzy"));
    let topic = &info["topics_with_message_count"][0];
    assert_eq!(topic["message_count"].as_u64(), Some(2));
    let meta = &topic["topic_metadata"];
    assert_eq!(meta["name"].as_str(), Some("/gait/frequency"));
    assert_eq!(meta["type"].as_str(), Some("std_msgs/msg/Float64"));
    assert_eq!(meta["serialization_format"].as_str(), Some("cdr"));
    assert_eq!(
        meta["type_description_hash"].as_str(),
        type_description_hash(&FLOAT64).as_deref()
    );

    // The channel carries the schema, the QoS and the hash.
    let bytes = std::fs::read(dir.join("layout_0.mcap")).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    let channel = summary.channels.values().next().unwrap();
    assert_eq!(channel.message_encoding, "cdr");
    let schema = channel.schema.as_ref().unwrap();
    assert_eq!(schema.name, "std_msgs/msg/Float64");
    assert_eq!(schema.encoding, "ros2msg");
    assert_eq!(&schema.data[..], FLOAT64.schema_text().as_bytes());
    assert_eq!(
        channel.metadata["topic_type_hash"].as_str(),
        meta["type_description_hash"].as_str().unwrap()
    );
}

#[test]
fn transient_local_topic_offers_the_qos_metadata_yaml_lists() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("qos");
    let mut writer = BagWriter::create(&dir).unwrap();
    writer
        .add_topic("/tf_static", &TF_MESSAGE, Durability::TransientLocal)
        .unwrap();
    // Declaring it again the same way is fine.
    writer
        .add_topic("/tf_static", &TF_MESSAGE, Durability::TransientLocal)
        .unwrap();
    writer
        .write("/tf_static", 0, &TFMessage::default())
        .unwrap();
    writer.write("/cmd_vel", 0, &Twist::default()).unwrap();
    let info = writer.finish().unwrap();

    let expected_latched = "\
- history: keep_last
  depth: 10
  reliability: reliable
  durability: transient_local
  deadline:
    sec: 9223372036
    nsec: 854775807
  lifespan:
    sec: 9223372036
    nsec: 854775807
  liveliness: automatic
  liveliness_lease_duration:
    sec: 9223372036
    nsec: 854775807
  avoid_ros_namespace_conventions: false";
    assert_eq!(
        Durability::TransientLocal.offered_qos_profiles_yaml(),
        expected_latched
    );
    let expected_volatile = expected_latched.replace("transient_local", "volatile");
    assert_eq!(
        Durability::Volatile.offered_qos_profiles_yaml(),
        expected_volatile
    );

    let channels = channel_metadata(&info.mcap_path);
    assert_eq!(
        channels["/tf_static"]["offered_qos_profiles"],
        expected_latched
    );
    assert_eq!(
        channels["/cmd_vel"]["offered_qos_profiles"],
        expected_volatile
    );
    // metadata.yaml holds the same profiles as a YAML list (version 9).
    let metadata = metadata_yaml(&dir);
    for topic in ["/tf_static", "/cmd_vel"] {
        let in_metadata = &topic_metadata(&metadata, topic)["offered_qos_profiles"];
        let in_channel: serde_yaml_ng::Value =
            serde_yaml_ng::from_str(&channels[topic]["offered_qos_profiles"]).unwrap();
        assert_eq!(in_metadata, &in_channel, "{topic}");
    }
}

#[test]
fn conflicting_declarations_name_the_topic_and_types() {
    let tmp = tempfile::tempdir().unwrap();
    let mut writer = BagWriter::create(&tmp.path().join("conflict")).unwrap();
    writer
        .write("/gait/frequency", 0, &Float64 { data: 1.0 })
        .unwrap();
    let err = writer
        .write("/gait/frequency", 1, &joint_state(1))
        .unwrap_err();
    let text = err.to_string();
    for part in [
        "/gait/frequency",
        "std_msgs/msg/Float64",
        "sensor_msgs/msg/JointState",
    ] {
        assert!(text.contains(part), "{text}");
    }
    let err = writer
        .write_cdr("/gait/frequency", &CLOCK, 1, &to_cdr(&Clock::default()))
        .unwrap_err();
    assert!(err.to_string().contains("rosgraph_msgs/msg/Clock"), "{err}");
    let err = writer
        .add_topic("/gait/frequency", &FLOAT64, Durability::TransientLocal)
        .unwrap_err();
    assert!(
        matches!(err, BagError::TopicDurabilityConflict { .. }),
        "{err}"
    );
    assert!(err.to_string().contains("/gait/frequency"), "{err}");
    let err = writer
        .write_cdr("/raw", &FLOAT64, 1, &[0x7f, 0x01])
        .unwrap_err();
    assert!(err.to_string().contains("/raw"), "{err}");
    let err = writer.write("", 1, &Float64::default()).unwrap_err();
    assert!(matches!(err, BagError::EmptyTopicName { .. }), "{err}");
    // The failed writes left the bag as it was.
    let info = writer.finish().unwrap();
    assert_eq!(info.message_count, 1);
    let reader = BagReader::open(&info.dir).unwrap();
    assert_eq!(reader.topics().len(), 1);
}

#[test]
fn create_refuses_a_non_empty_directory() {
    let tmp = tempfile::tempdir().unwrap();
    std::fs::write(tmp.path().join("other.txt"), "x").unwrap();
    let err = BagWriter::create(tmp.path()).err().unwrap();
    assert!(matches!(err, BagError::DirNotEmpty { .. }), "{err}");
    assert!(
        err.to_string().contains(&tmp.path().display().to_string()),
        "{err}"
    );
    // An existing empty directory is fine.
    let empty = tmp.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    BagWriter::create(&empty).unwrap().finish().unwrap();
    let reader = BagReader::open(&empty).unwrap();
    assert!(reader.topics().is_empty());
    assert_eq!(reader.start_time_ns(), None);
    assert_eq!(reader.metadata_counts(), Some(vec![]));
}

#[test]
fn dropping_the_writer_finishes_the_bag() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("dropped");
    {
        let mut writer = BagWriter::create(&dir).unwrap();
        writer
            .add_topic("/robot_description", &STRING, Durability::TransientLocal)
            .unwrap();
        writer
            .write(
                "/robot_description",
                0,
                &StringMsg {
                    data: "urdf".into(),
                },
            )
            .unwrap();
        for i in 0..4 {
            writer
                .write("/joint_states", i * 10, &joint_state(i * 10))
                .unwrap();
        }
    }
    assert!(dir.join(METADATA_FILE_NAME).is_file());
    let reader = BagReader::open(&dir).unwrap();
    assert_eq!(reader.read::<JointState>("/joint_states").unwrap().len(), 4);
    assert_eq!(
        reader.metadata_counts().unwrap(),
        [
            ("/joint_states".to_string(), 4),
            ("/robot_description".to_string(), 1)
        ]
    );
    let metadata = metadata_yaml(&dir);
    let qos = &topic_metadata(&metadata, "/robot_description")["offered_qos_profiles"];
    assert_eq!(qos[0]["durability"].as_str(), Some("transient_local"));

    // A panic while recording also leaves a readable bag.
    let dir = tmp.path().join("panicked");
    let panic_dir = dir.clone();
    let result = std::panic::catch_unwind(move || {
        let mut writer = BagWriter::create(&panic_dir).unwrap();
        writer.write("/clock", 7, &Clock::default()).unwrap();
        panic!("simulation blew up");
    });
    assert!(result.is_err());
    let reader = BagReader::open(&dir).unwrap();
    assert_eq!(reader.read::<Clock>("/clock").unwrap()[0].0, 7);
}

#[test]
fn unreadable_input_names_the_file() {
    let tmp = tempfile::tempdir().unwrap();
    let contains_path = |err: BagError, path: &Path| {
        let text = err.to_string();
        assert!(text.contains(&path.display().to_string()), "{text}");
    };

    let missing = tmp.path().join("missing");
    contains_path(BagReader::open(&missing).err().unwrap(), &missing);

    let not_mcap = tmp.path().join("notes.mcap");
    std::fs::write(&not_mcap, "plain text, not MCAP").unwrap();
    let err = BagReader::open(&not_mcap).err().unwrap();
    assert!(matches!(err, BagError::Mcap { .. }), "{err}");
    contains_path(err, &not_mcap);

    let empty_dir = tmp.path().join("no_mcap");
    std::fs::create_dir(&empty_dir).unwrap();
    let err = BagReader::open(&empty_dir).err().unwrap();
    assert!(matches!(err, BagError::NoMcap { .. }), "{err}");
    contains_path(err, &empty_dir);

    // A bag whose MCAP is cut in half.
    let dir = tmp.path().join("cut");
    let mut writer = BagWriter::create(&dir).unwrap();
    for i in 0..50 {
        writer.write("/odom", i, &odometry(i, i as f64)).unwrap();
    }
    let info = writer.finish().unwrap();
    let bytes = std::fs::read(&info.mcap_path).unwrap();
    std::fs::write(&info.mcap_path, &bytes[..bytes.len() / 2]).unwrap();
    // Read as a killed recording: what its complete chunks hold (the one chunk lies before
    // the cut, in the summary), with a warning naming the file.
    let reader = BagReader::open(&dir).unwrap();
    let warning = reader.warnings().join("\n");
    assert!(warning.contains("unfinished"), "{warning}");
    assert!(
        warning.contains(&info.mcap_path.display().to_string()),
        "{warning}"
    );
    let recovered = reader.read::<Odometry>("/odom").unwrap();
    assert_eq!(recovered.len(), 50);
    assert_eq!(recovered[49].0, 49);

    // metadata.yaml listing a file that is not there.
    std::fs::remove_file(&info.mcap_path).unwrap();
    contains_path(BagReader::open(&dir).err().unwrap(), &info.mcap_path);

    // A broken metadata.yaml.
    let metadata_path = dir.join(METADATA_FILE_NAME);
    std::fs::write(&metadata_path, "rosbag2_bagfile_information: [").unwrap();
    let err = BagReader::open(&dir).err().unwrap();
    assert!(matches!(err, BagError::Metadata { .. }), "{err}");
    contains_path(err, &metadata_path);
}

#[test]
fn read_errors_name_topic_types_and_index() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("errors");
    let mut writer = BagWriter::create(&dir).unwrap();
    writer.write("/odom", 0, &odometry(0, 0.0)).unwrap();
    writer.write("/odom", 1, &odometry(1, 1.0)).unwrap();
    // A valid header, then a body far too short for an Odometry.
    writer
        .write_cdr("/odom", &ODOMETRY, 2, &[0, 1, 0, 0, 1])
        .unwrap();
    writer.finish().unwrap();
    let reader = BagReader::open(&dir).unwrap();

    let text = reader.read::<Odometry>("/tf").unwrap_err().to_string();
    assert!(text.contains("/tf") && text.contains("/odom"), "{text}");
    let text = reader.read::<JointState>("/odom").unwrap_err().to_string();
    for part in [
        "/odom",
        "nav_msgs/msg/Odometry",
        "sensor_msgs/msg/JointState",
    ] {
        assert!(text.contains(part), "{text}");
    }
    let err = reader.read::<Odometry>("/odom").unwrap_err();
    assert!(matches!(err, BagError::Decode { index: 2, .. }), "{err}");
    let text = err.to_string();
    assert!(
        text.contains("/odom") && text.contains("message 2"),
        "{text}"
    );
}

#[test]
fn reads_mcap_files_of_other_writers() {
    // A file as another tool may write it: no ros2 profile, schema name without `/msg/`,
    // lz4 chunks, no metadata.yaml, a second channel that is not CDR.
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("foreign.mcap");
    {
        let file = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
        let mut mcap = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Lz4))
            .create(file)
            .unwrap();
        let schema = mcap
            .add_schema(
                "geometry_msgs/Twist",
                "ros2msg",
                TWIST.schema_text().as_bytes(),
            )
            .unwrap();
        let channel = mcap
            .add_channel(schema, "/cmd_vel", "cdr", &BTreeMap::new())
            .unwrap();
        let json_channel = mcap
            .add_channel(0, "/notes", "json", &BTreeMap::new())
            .unwrap();
        let twist = Twist {
            linear: [0.3, 0.0, 0.0].into(),
            angular: [0.0, 0.0, 0.5].into(),
        };
        for (i, t) in [30u64, 10, 20].into_iter().enumerate() {
            let header = mcap::records::MessageHeader {
                channel_id: channel,
                sequence: i as u32,
                log_time: t,
                publish_time: t,
            };
            mcap.write_to_known_channel(&header, &to_cdr(&twist))
                .unwrap();
        }
        let header = mcap::records::MessageHeader {
            channel_id: json_channel,
            sequence: 0,
            log_time: 5,
            publish_time: 5,
        };
        mcap.write_to_known_channel(&header, b"{}").unwrap();
        mcap.finish().unwrap();
    }
    let reader = BagReader::open(&path).unwrap();
    assert_eq!(
        reader.topics(),
        [
            TopicInfo {
                name: "/cmd_vel".into(),
                type_name: "geometry_msgs/msg/Twist".into(),
                message_count: 3
            },
            TopicInfo {
                name: "/notes".into(),
                type_name: String::new(),
                message_count: 1
            }
        ]
    );
    let times: Vec<u64> = reader
        .read::<Twist>("/cmd_vel")
        .unwrap()
        .iter()
        .map(|(t, _)| *t)
        .collect();
    assert_eq!(times, [10, 20, 30]);
    assert_eq!(reader.topics_of_type(&TWIST), ["/cmd_vel"]);
    assert_eq!(
        (reader.start_time_ns(), reader.end_time_ns()),
        (Some(5), Some(30))
    );
    let err = reader.read::<Twist>("/notes").unwrap_err();
    assert!(matches!(err, BagError::Encoding { .. }), "{err}");
}

#[test]
fn type_hashes_match_ros_jazzy() {
    // Values of `ros2 topic info -v` on Jazzy, as rosbags computes them from the Jazzy
    // message definitions.
    let known = [
        (
            &STRING,
            "df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18",
        ),
        (
            &TIME,
            "b106235e25a4c5ed35098aa0a61a3ee9c9b18d197f398b0e4206cea9acf9c197",
        ),
        (
            &CLOCK,
            "692f7a66e93a3c83e71765d033b60349ba68023a8c689a79e48078bcb5c58564",
        ),
        (
            &ODOMETRY,
            "3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0",
        ),
        (
            &JOINT_STATE,
            "a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e",
        ),
        (
            &POINT_CLOUD2,
            "9198cabf7da3796ae6fe19c4cb3bdd3525492988c70522628af5daa124bae2b5",
        ),
        (
            &TF_MESSAGE,
            "e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087",
        ),
        (
            &FLOAT64_MULTI_ARRAY,
            "1025ddc6b9552d191f89ef1a8d2f60f3d373e28b283d8891ddcc974e8c55397f",
        ),
        (
            &WRENCH_STAMPED,
            "8dc3deaf06b2ab281f9f9a742a8961c328ca7cec16e3fd6586d3a5c83fa78f77",
        ),
        (
            &POSE_STAMPED,
            "10f3786d7d40fd2b54367835614bff85d4ad3b5dab62bf8bca0cc232d73b4cd8",
        ),
        (
            &TWIST,
            "9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a",
        ),
    ];
    for (ty, hex) in known {
        assert_eq!(
            type_description_hash(ty).as_deref(),
            Some(format!("RIHS01_{hex}").as_str()),
            "{}",
            ty.type_name()
        );
    }
}

#[test]
fn reads_metadata_of_older_rosbag2_versions() {
    // rosbag2 before Jazzy: QoS as a YAML string, file paths with the bag directory in front.
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("humble");
    let mut writer = BagWriter::create(&dir).unwrap();
    writer.write("/cmd_vel", 3, &Twist::default()).unwrap();
    writer.finish().unwrap();
    let old_metadata = "\
rosbag2_bagfile_information:
  version: 5
  storage_identifier: mcap
  relative_file_paths:
    - humble/humble_0.mcap
  duration:
    nanoseconds: 0
  starting_time:
    nanoseconds_since_epoch: 3
  message_count: 1
  topics_with_message_count:
    - topic_metadata:
        name: /cmd_vel
        type: geometry_msgs/msg/Twist
        serialization_format: cdr
        offered_qos_profiles: \"- history: 3\\n  depth: 0\\n  reliability: 1\\n\"
      message_count: 1
  compression_format: \"\"
  compression_mode: \"\"
";
    let metadata_path = dir.join(METADATA_FILE_NAME);
    std::fs::write(&metadata_path, old_metadata).unwrap();
    // Opening the metadata file itself opens its bag.
    let reader = BagReader::open(&metadata_path).unwrap();
    assert_eq!(reader.files(), [dir.join("humble_0.mcap")]);
    assert_eq!(
        reader.metadata_counts().unwrap(),
        [("/cmd_vel".to_string(), 1)]
    );
    assert_eq!(reader.read::<Twist>("/cmd_vel").unwrap()[0].0, 3);

    // A sqlite3 bag is refused with the reason.
    std::fs::write(
        &metadata_path,
        old_metadata.replace("storage_identifier: mcap", "storage_identifier: sqlite3"),
    )
    .unwrap();
    let text = BagReader::open(&dir).err().unwrap().to_string();
    assert!(
        text.contains("sqlite3") && text.contains(METADATA_FILE_NAME),
        "{text}"
    );
}
