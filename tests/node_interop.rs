//! The `sandstep node` binary against independent software: an Eclipse Cyclone DDS peer in
//! Python reads its topics and drives it, and a SIGINT in the middle of a run leaves a bag that
//! the project's reader and the Python readers (`mcap`, `rosbags`) open. All DDS traffic stays
//! on loopback, in a domain of the test's own.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use sandstep::bag::BagReader;

const CYCLONE_LOOPBACK: &str = r#"<CycloneDDS><Domain Id="any"><General><Interfaces><NetworkInterface name="lo"/></Interfaces></General></Domain></CycloneDDS>"#;

fn crate_dir() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// A DDS domain no other test run on this machine uses at the same moment.
fn test_domain(offset: u16) -> u16 {
    150 + (std::process::id() % 20) as u16 * 4 + offset
}

/// Starts `sandstep node` with `args` in the crate directory, in `domain`.
fn spawn_node(domain: u16, args: &[&str]) -> Child {
    Command::new(env!("CARGO_BIN_EXE_sandstep"))
        .arg("node")
        .args(args)
        .args(["--set", "node.loopback_only=true", "--json"])
        .current_dir(crate_dir())
        .env("ROS_DOMAIN_ID", domain.to_string())
        .env("ROS_DISTRO", "jazzy")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start sandstep node")
}

/// Waits for `child` up to `timeout`; kills it and panics if it is still running.
fn wait_output(mut child: Child, timeout: Duration) -> std::process::Output {
    let deadline = Instant::now() + timeout;
    while Instant::now() < deadline {
        if child.try_wait().unwrap().is_some() {
            return child.wait_with_output().unwrap();
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    child.kill().ok();
    let out = child.wait_with_output().unwrap();
    panic!(
        "still running after {timeout:?}; stderr:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn json_line(out: &std::process::Output, what: &str) -> serde_json::Value {
    json_line_exiting(out, what, 0)
}

/// The JSON summary of a process that exited with `code` (130 after SIGINT).
fn json_line_exiting(out: &std::process::Output, what: &str, code: i32) -> serde_json::Value {
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        out.status.code(),
        Some(code),
        "{what} exited with {} (expected {code}):\n{stderr}\n{stdout}",
        out.status
    );
    serde_json::from_str(stdout.lines().last().unwrap_or_default())
        .unwrap_or_else(|e| panic!("{what}: no JSON ({e}):\n{stdout}\n{stderr}"))
}

#[test]
fn cyclone_dds_peer_reads_the_robot_and_reverses_it() {
    let domain = test_domain(0);
    let bag_root = tempfile::tempdir().unwrap();
    let bag = bag_root.path().join("interop");
    let bag_arg = bag.to_str().unwrap();
    let node = spawn_node(
        domain,
        &[
            "config/robot_on_ground.yaml",
            "--realtime",
            "--duration",
            "14",
            "--set",
            "robot.gait.frequency_hz=2",
            "--bag",
            bag_arg,
        ],
    );
    // The peer: 4 s reading the default gait, then 7 s commanding -2 Hz (the robot needs a
    // second of sim time to turn its gait round, and on a loaded machine the node's sim time
    // falls behind the peer's wall clock; 5 s was not always enough).
    let peer = Command::new(common::python())
        .arg(crate_dir().join("tests/python/dds_peer.py"))
        .args(["4", "7", "-2.0"])
        .env("ROS_DOMAIN_ID", domain.to_string())
        .env("CYCLONEDDS_URI", CYCLONE_LOOPBACK)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start the Python peer");
    let peer = json_line(&wait_output(peer, Duration::from_secs(60)), "dds_peer.py");
    let node = json_line(&wait_output(node, Duration::from_secs(60)), "sandstep node");

    let count = |t: &str| peer["counts"][t].as_u64().unwrap();
    // 11 s at 100 Hz of sim time in real time; discovery eats the first few hundred ms.
    for topic in ["clock", "joint_states", "odom"] {
        assert!(
            count(topic) > 500,
            "peer got {} {topic}: {peer}",
            count(topic)
        );
    }
    assert_eq!(peer["clock_increasing"], true, "{peer}");
    assert_eq!(peer["joint_lengths_ok"], true, "{peer}");
    let names: Vec<&str> = peer["joint_names"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| n.as_str().unwrap())
        .collect();
    assert_eq!(names.len(), 6, "{names:?}");
    assert!(names.contains(&"leg_front_left_joint"), "{names:?}");
    assert_eq!(peer["odom_frame"], "odom");
    assert_eq!(peer["odom_child"], "base_link");
    let height = peer["body_height_m"].as_f64().unwrap();
    assert!((0.0..0.2).contains(&height), "body height {height} m");
    let before = peer["speed_before_m_s"].as_f64().unwrap();
    let after = peer["speed_after_m_s"].as_f64().unwrap();
    assert!(before > 0.01, "2 Hz forward: speed {before} m/s");
    assert!(after < -0.01, "after the peer's -2 Hz: speed {after} m/s");

    assert!(node["commands_received"].as_u64().unwrap() >= 20, "{node}");
    let reader = BagReader::open(&bag).unwrap();
    let gait = reader
        .read::<sandstep::msgs::Float64>("/gait/frequency")
        .unwrap();
    assert!(gait.len() >= 20 && gait.iter().all(|(_, f)| f.data == -2.0));
}

/// Sends SIGINT to a running process.
fn interrupt(child: &Child) {
    let status = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
}

/// Message counts per topic from a Python reader's JSON.
fn python_counts(script: &str, bag: &Path) -> Vec<(String, u64)> {
    let json = common::run_python_json(script, &[bag]);
    let mut counts: Vec<(String, u64)> = json["topics"]
        .as_object()
        .unwrap()
        .iter()
        .map(|(name, t)| (name.clone(), t["messages"].as_array().unwrap().len() as u64))
        .collect();
    counts.sort();
    counts
}

#[test]
fn sigint_mid_run_leaves_a_bag_every_reader_opens() {
    let domain = test_domain(1);
    let bag_root = tempfile::tempdir().unwrap();
    let bag: PathBuf = bag_root.path().join("interrupted");
    // The robot on sand, coarse so that it moves within seconds, on the whole bed (the shipped
    // sand window's 5 cm step is not a whole number of 2 cm cells); no --duration: runs until
    // stopped.
    let node = spawn_node(
        domain,
        &[
            "config/robot_on_sand.yaml",
            "--set",
            "sand.dx_m=0.02",
            "--set",
            "sand.window=null",
            "--bag",
            bag.to_str().unwrap(),
        ],
    );
    // Wait until the node has published for a while (its bag has an .mcap growing).
    std::thread::sleep(Duration::from_secs(8));
    interrupt(&node);
    let out = wait_output(node, Duration::from_secs(60));
    // Stopped by SIGINT, its outputs finished: exit code 128 + 2.
    let summary = json_line_exiting(&out, "interrupted sandstep node", 130);
    let sim_time = summary["sim_time_s"].as_f64().unwrap();
    assert!(sim_time > 0.05, "simulated only {sim_time} s");

    let reader = BagReader::open(&bag).unwrap();
    let mut ours: Vec<(String, u64)> = reader
        .topics()
        .iter()
        .map(|t| (t.name.clone(), t.message_count))
        .collect();
    ours.sort();
    let metadata = {
        let mut m = reader
            .metadata_counts()
            .expect("metadata.yaml written on SIGINT");
        m.sort();
        m
    };
    // Topics that never got a message (the commands) are declared but empty.
    let nonempty = |v: &[(String, u64)]| -> Vec<(String, u64)> {
        v.iter().filter(|(_, n)| *n > 0).cloned().collect()
    };
    assert_eq!(
        nonempty(&ours),
        nonempty(&metadata),
        "reader vs metadata.yaml"
    );
    let names: Vec<&str> = ours.iter().map(|(n, _)| n.as_str()).collect();
    for topic in [
        "/clock",
        "/joint_states",
        "/odom",
        "/tf",
        "/tf_static",
        "/robot_description",
        "/body_pose",
        "/body_wrench",
        "/leg_wrenches/leg_front_left",
        "/leg_wrenches/leg_rear_right",
        "/sand/surface",
    ] {
        assert!(names.contains(&topic), "{topic} missing from {names:?}");
    }
    let odom = ours.iter().find(|(n, _)| n == "/odom").unwrap().1;
    assert!(
        (odom as f64 - sim_time * 100.0).abs() <= 2.0,
        "{odom} odometry messages for {sim_time} s at 100 Hz"
    );
    assert_eq!(
        nonempty(&python_counts("read_bag_mcap.py", &bag)),
        nonempty(&ours)
    );
    assert_eq!(
        nonempty(&python_counts("read_bag_rosbags.py", &bag)),
        nonempty(&ours)
    );
    // The sand pushes the legs: some leg feels a force.
    let wrenches = reader
        .read::<sandstep::msgs::WrenchStamped>("/leg_wrenches/leg_front_left")
        .unwrap();
    let peak = wrenches
        .iter()
        .map(|(_, w)| {
            let f = w.wrench.force;
            (f.x * f.x + f.y * f.y + f.z * f.z).sqrt()
        })
        .fold(0.0, f64::max);
    assert!(peak > 0.01, "peak leg force {peak} N");
}

/// Wall time a killed recording may lose at most (s): the writer closes its chunk at least
/// every second (issue 22 asks for every message older than two seconds back).
const MAY_LOSE_S: f64 = 2.0;

/// A recording killed with SIGKILL (no chance to finish its bag) loses at most its last
/// seconds: `sandstep analyze` reads the complete chunks with a warning, and `sandstep bag
/// reindex` finishes the bag, which every reader then opens, holding every message written
/// more than two seconds before the kill. `--realtime` on rigid ground paces the sim clock to
/// the wall clock, so a message's stamp tells when it was written.
#[test]
fn sigkill_loses_only_the_last_second_and_reindex_finishes_the_bag() {
    let domain = test_domain(2);
    let bag_root = tempfile::tempdir().unwrap();
    let bag: PathBuf = bag_root.path().join("killed");
    let node = spawn_node(
        domain,
        &[
            "config/robot_on_ground.yaml",
            "--realtime",
            "--bag",
            bag.to_str().unwrap(),
        ],
    );
    let mcap = bag.join("killed_0.mcap");
    let deadline = Instant::now() + Duration::from_secs(60);
    while !mcap.exists() {
        assert!(Instant::now() < deadline, "no bag at {}", mcap.display());
        std::thread::sleep(Duration::from_millis(20));
    }
    // The node opens the bag, then starts its clock at 0 in real time.
    let recording_since = Instant::now();
    std::thread::sleep(Duration::from_secs(6));
    let killed_after_s = recording_since.elapsed().as_secs_f64();
    let status = Command::new("kill")
        .args(["-KILL", &node.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let out = node.wait_with_output().unwrap();
    assert_eq!(out.status.code(), None, "killed, not exited");
    assert!(
        !bag.join("metadata.yaml").exists(),
        "nothing finished the bag"
    );

    let analyze = Command::new(env!("CARGO_BIN_EXE_sandstep"))
        .args(["analyze", bag.to_str().unwrap()])
        .output()
        .unwrap();
    let report = String::from_utf8_lossy(&analyze.stdout);
    assert!(analyze.status.success(), "{report}\n{analyze:?}");
    assert!(report.contains("unfinished"), "{report}");

    let reindex = Command::new(env!("CARGO_BIN_EXE_sandstep"))
        .args(["bag", "reindex", bag.to_str().unwrap(), "--json"])
        .output()
        .unwrap();
    assert!(reindex.status.success(), "{reindex:?}");
    let reader = BagReader::open(&bag).unwrap();
    assert!(reader.warnings().is_empty(), "{:?}", reader.warnings());
    let clock = reader.read::<sandstep::msgs::Clock>("/clock").unwrap();
    let stamps: Vec<f64> = clock
        .iter()
        .map(|(_, c)| c.clock.sec as f64 + c.clock.nanosec as f64 * 1e-9)
        .collect();
    let last = *stamps.last().expect("clock messages recovered");
    println!(
        "killed {killed_after_s:.2} s into the recording; recovered /clock up to {last:.2} s \
         ({} messages)",
        stamps.len()
    );
    assert!(
        last >= killed_after_s - MAY_LOSE_S,
        "recovered up to {last} s of a recording killed after {killed_after_s} s"
    );
    // Every message up to there: the 100 Hz clock has no gap longer than the node's own
    // (one period skipped once in a while, in finished bags too), and its count matches.
    let largest_gap = stamps.windows(2).map(|w| w[1] - w[0]).fold(0.0, f64::max);
    assert!(largest_gap < 0.025, "a gap of {largest_gap} s in /clock");
    let expected = last * 100.0 + 1.0;
    assert!(
        (stamps.len() as f64 - expected).abs() <= 2.0,
        "{} clock messages up to {last} s at 100 Hz",
        stamps.len()
    );
    let ours: Vec<(String, u64)> = {
        let mut v: Vec<(String, u64)> = reader
            .topics()
            .iter()
            .filter(|t| t.message_count > 0)
            .map(|t| (t.name.clone(), t.message_count))
            .collect();
        v.sort();
        v
    };
    let mut metadata = reader.metadata_counts().expect("metadata.yaml written");
    metadata.retain(|(_, n)| *n > 0);
    metadata.sort();
    assert_eq!(metadata, ours, "metadata.yaml against the MCAP");
    let nonempty = |mut v: Vec<(String, u64)>| {
        v.retain(|(_, n)| *n > 0);
        v
    };
    assert_eq!(nonempty(python_counts("read_bag_mcap.py", &bag)), ours);
    assert_eq!(nonempty(python_counts("read_bag_rosbags.py", &bag)), ours);
}
