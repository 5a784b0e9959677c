//! The ROS 2 node in-process: a second ros2-client node on the same (loopback-only, test-
//! specific) domain reads the robot's topics, commands a gait frequency, pauses and resets the
//! simulation, and the bag records all of it.

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use ros2_client::{
    Context, MessageTypeName, Name, Node, NodeName, NodeOptions, ServiceMapping, ServiceTypeName,
};
use sandstep::bag::BagReader;
use sandstep::msgs::{
    Clock, Float64, JointState, Odometry, RosMessage, ServiceResponse, SetBoolRequest,
    TriggerRequest,
};
use sandstep::ros::qos;
use sandstep::ros::{run_node, NodeRunOptions};
use sandstep::scene::Scene;

/// A DDS domain no other test run on this machine uses at the same moment.
fn test_domain(offset: u16) -> u16 {
    100 + (std::process::id() % 50) as u16 * 2 + offset
}

fn peer_node(domain: u16) -> Node {
    let participant = rustdds::DomainParticipantBuilder::new(domain)
        .with_only_networks([std::net::Ipv4Addr::LOCALHOST])
        .build()
        .unwrap();
    let context = Context::from_domain_participant(participant).unwrap();
    let mut node = context
        .new_node(NodeName::new("/", "test_peer").unwrap(), NodeOptions::new())
        .unwrap();
    let spinner = node.spinner().unwrap();
    std::thread::spawn(move || smol::block_on(spinner.spin()));
    node
}

fn subscribe<M: RosMessage + ros2_client::Message>(
    node: &mut Node,
    name: &str,
) -> ros2_client::Subscription<M> {
    let qos = qos::publisher(sandstep::bag::Durability::Volatile);
    let ty = M::TYPE;
    let topic = node
        .create_topic(
            &Name::parse(name).unwrap(),
            MessageTypeName::new(ty.package, ty.name),
            &qos,
        )
        .unwrap();
    node.create_subscription(&topic, Some(qos)).unwrap()
}

/// Every message waiting on `sub`.
fn drain<M: 'static + serde::de::DeserializeOwned>(sub: &ros2_client::Subscription<M>) -> Vec<M> {
    let mut out = Vec::new();
    while let Ok(Some((m, _))) = sub.take() {
        out.push(m);
    }
    out
}

/// Calls a service, retrying until discovery has matched it, within `timeout`.
fn call<Req, Resp>(client: &ros2_client::Client<Req, Resp>, request: Req, timeout: Duration) -> Resp
where
    Req: ros2_client::Message + Clone + 'static,
    Resp: ros2_client::Message + 'static,
{
    let deadline = Instant::now() + timeout;
    while Instant::now() < deadline {
        let attempt = smol::block_on(smol::future::or(
            async { Some(client.async_call_service(request.clone()).await) },
            async {
                smol::Timer::after(Duration::from_secs(2)).await;
                None
            },
        ));
        if let Some(Ok(response)) = attempt {
            return response;
        }
    }
    panic!("no service response within {timeout:?}");
}

#[test]
fn node_publishes_obeys_commands_pauses_resets_and_records() {
    std::env::set_var("ROS_DISTRO", "jazzy");
    let domain = test_domain(0);
    std::env::set_var("ROS_DOMAIN_ID", domain.to_string());
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    std::env::set_current_dir(root).unwrap();
    let scene = Scene::load(
        Path::new("config/robot_on_ground.yaml"),
        &[
            "node.loopback_only=true".into(),
            "robot.gait.frequency_hz=2".into(),
        ],
    )
    .unwrap();
    let bag_root = tempfile::tempdir().unwrap();
    let bag_dir = bag_root.path().join("node_bag");
    let stop = Arc::new(AtomicBool::new(false));
    let opts = NodeRunOptions {
        duration_s: None,
        realtime: true,
        bag_dir: Some(bag_dir.clone()),
        progress: Default::default(),
        stop: stop.clone(),
    };
    let node_thread = std::thread::spawn(move || run_node(&scene, &opts));

    let mut peer = peer_node(domain);
    let odom = subscribe::<Odometry>(&mut peer, "/odom");
    let joints = subscribe::<JointState>(&mut peer, "/joint_states");
    let clock = subscribe::<Clock>(&mut peer, "/clock");
    let frequency_topic = peer
        .create_topic(
            &Name::parse("/gait/frequency").unwrap(),
            MessageTypeName::new("std_msgs", "Float64"),
            &qos::command(),
        )
        .unwrap();
    let frequency = peer
        .create_publisher::<Float64>(&frequency_topic, Some(qos::command()))
        .unwrap();
    let svc_qos = qos::service();
    let pause = peer
        .create_client::<SetBoolRequest, ServiceResponse>(
            ServiceMapping::Enhanced,
            &Name::parse("/sandstep/pause").unwrap(),
            &ServiceTypeName::new("std_srvs", "SetBool"),
            svc_qos.clone(),
            svc_qos.clone(),
        )
        .unwrap();
    let reset = peer
        .create_client::<TriggerRequest, ServiceResponse>(
            ServiceMapping::Enhanced,
            &Name::parse("/sandstep/reset").unwrap(),
            &ServiceTypeName::new("std_srvs", "Trigger"),
            svc_qos.clone(),
            svc_qos,
        )
        .unwrap();

    // Phase 1: the scene's gait (2 Hz forward) for 2 s of simulated (= wall) time.
    let mut poses: Vec<(f64, f64)> = Vec::new(); // (stamp s, x m)
    let collect = |poses: &mut Vec<(f64, f64)>, wall: Duration| {
        let end = Instant::now() + wall;
        while Instant::now() < end {
            for m in drain(&odom) {
                poses.push((m.header.stamp.as_secs(), m.pose.pose.position.x));
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    };
    collect(&mut poses, Duration::from_secs(3));
    assert!(
        poses.len() > 50,
        "only {} odometry messages in 3 s",
        poses.len()
    );
    let x_forward = poses.last().unwrap().1;
    let js = drain(&joints);
    assert!(!js.is_empty(), "no joint_states");
    assert_eq!(js[0].name.len(), 6);
    assert!(js[0]
        .name
        .iter()
        .all(|n| n.starts_with("leg_") && n.ends_with("_joint")));
    let clocks: Vec<f64> = drain(&clock).iter().map(|c| c.clock.as_secs()).collect();
    assert!(
        clocks.windows(2).all(|w| w[1] > w[0]),
        "clock not increasing"
    );
    assert!(
        x_forward > 0.02,
        "the default gait did not walk forward: x = {x_forward}"
    );

    // Phase 2: command -2 Hz (backward) for 3 s, re-sent like a controller does.
    let mark = poses.len();
    let end = Instant::now() + Duration::from_secs(3);
    while Instant::now() < end {
        frequency.publish(Float64 { data: -2.0 }).unwrap();
        collect(&mut poses, Duration::from_millis(100));
    }
    let (t_cmd, x_cmd) = poses[mark];
    let (t_end, x_end) = *poses.last().unwrap();
    let speed = (x_end - x_cmd) / (t_end - t_cmd);
    assert!(
        speed < -0.01,
        "after /gait/frequency = -2 the robot should walk backward; mean speed {speed} m/s"
    );

    // Pause: the clock stops; unpause: it runs again.
    let r = call(
        &pause,
        SetBoolRequest { data: true },
        Duration::from_secs(20),
    );
    assert!(r.success, "{r:?}");
    std::thread::sleep(Duration::from_millis(300));
    drain(&clock);
    std::thread::sleep(Duration::from_millis(700));
    assert!(drain(&clock).is_empty(), "the clock ran while paused");
    assert!(
        call(
            &pause,
            SetBoolRequest { data: false },
            Duration::from_secs(20)
        )
        .success
    );

    // Reset: back at the start, the clock keeps counting up from where it was.
    let r = call(&reset, TriggerRequest::default(), Duration::from_secs(20));
    assert!(r.success, "{r:?}");
    let t_reset: f64 = r
        .message
        .rsplit("t = ")
        .next()
        .and_then(|s| s.trim_end_matches(" s").parse().ok())
        .unwrap_or_else(|| panic!("no reset time in {:?}", r.message));
    assert!(
        t_reset > t_end,
        "the clock went back: reset at {t_reset}, last odom {t_end}"
    );
    let mut after = Vec::new();
    collect(&mut after, Duration::from_millis(500));
    let first_after = after
        .iter()
        .find(|(t, _)| *t > t_reset + 1e-6)
        .expect("odometry after the reset");
    assert!(
        first_after.1.abs() < 0.02,
        "after reset the robot should be back near x = 0, is at {}",
        first_after.1
    );

    stop.store(true, Ordering::Relaxed);
    let summary = node_thread.join().unwrap().expect("node ran");
    assert_eq!(summary.resets, 1);
    assert!(summary.commands_received >= 10, "{summary:?}");
    assert!(
        summary.real_time_factor <= 1.01,
        "--realtime never runs ahead of the wall clock: real-time factor {}",
        summary.real_time_factor
    );

    // The bag holds the commands received and the state published.
    let bag = BagReader::open(&bag_dir).unwrap();
    let count = |topic: &str| {
        bag.topics()
            .iter()
            .find(|t| t.name == topic)
            .map_or(0, |t| t.message_count)
    };
    assert!(count("/gait/frequency") >= 10);
    assert!(count("/odom") > 500, "{:?}", bag.topics());
    assert_eq!(count("/robot_description"), 1);
    assert_eq!(count("/tf_static"), 1);
    let recorded: Vec<(u64, Float64)> = bag.read("/gait/frequency").unwrap();
    assert!(recorded.iter().all(|(_, f)| f.data == -2.0));
}
