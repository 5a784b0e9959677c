//! `sandstep analyze` on synthetic bags with known motion: the library call and the CLI.
//!
//! The bag: the body moves at 0.10 m/s along x for 3 s with a 2 Hz vertical bob, the legs
//! turn at 2 Hz in two tripods, each leg's sand force points up with a known magnitude, the
//! sand surface is flat at z = 0 and the legs are thin boxes hanging from their hips.

use std::collections::BTreeMap;
use std::f64::consts::{PI, TAU};
use std::path::{Path, PathBuf};
use std::process::Command;

use nalgebra::{UnitQuaternion, Vector3 as Vec3};
use sandstep::analysis::bag::{
    analyze_bag, analyze_bag_with, AnalysisOptions, BagAnalysis, SPEED_WINDOW_S,
};
use sandstep::analysis::plots::write_plots;
use sandstep::bag::{BagWriter, Durability};
use sandstep::msgs::*;

const NS_PER_S: f64 = 1e9;
/// Sample rate of poses, joints, tf and wrenches (Hz).
const RATE_HZ: f64 = 100.0;
/// Samples: 0 to 3 s inclusive.
const SAMPLES: usize = 301;
const SPEED_M_S: f64 = 0.10;
const GAIT_HZ: f64 = 2.0;
/// Mean body height (m) and bob amplitude (m): z = mean - amplitude cos(2π f t).
const BODY_HEIGHT_M: f64 = 0.035;
const BOB_M: f64 = 0.002;
/// Hips sit this far below the body origin (m).
const HIP_Z_M: f64 = -0.01;
/// Leg box size (m): along x (thickness), y (width), z (length, hanging down from the hip).
const LEG_SIZE_M: [f64; 3] = [0.004, 0.01, 0.04];
/// Sand force magnitude scale of leg i: (i + 1) times this (N).
const FORCE_SCALE_N: f64 = 0.1;
/// The sand's force on the body in the synthetic bag (N, base_link frame, which stays level):
/// drag backwards, support upwards.
const BODY_FORCE_N: [f64; 3] = [-0.2, 0.0, 0.5];
/// Surface cloud rate (Hz).
const SURFACE_RATE_HZ: f64 = 2.0;
/// Wall-clock log times of the "other tool" bag start here (ns since the epoch).
const WALL_START_NS: u64 = 1_700_000_000_000_000_000;
/// ... and run this much slower than simulated time.
const WALL_PER_SIM: f64 = 1.7;

/// Leg link names, hip (x, y) and gait phase (rad): two alternating tripods.
const LEGS: [(&str, f64, f64, f64); 6] = [
    ("leg_front_left", 0.06, 0.025, 0.0),
    ("leg_middle_left", 0.0, 0.025, PI),
    ("leg_rear_left", -0.06, 0.025, 0.0),
    ("leg_front_right", 0.06, -0.025, PI),
    ("leg_middle_right", 0.0, -0.025, 0.0),
    ("leg_rear_right", -0.06, -0.025, PI),
];

fn urdf() -> String {
    let mut text = String::from(
        r#"<?xml version="1.0"?>
<robot name="test_hexapod">
  <link name="base_link"><collision><geometry><box size="0.13 0.02 0.025"/></geometry></collision></link>
"#,
    );
    let [sx, sy, sz] = LEG_SIZE_M;
    for (name, x, y, _) in LEGS {
        text += &format!(
            r#"  <link name="{name}"><collision><origin xyz="0 0 {}" rpy="0 0 0"/><geometry><box size="{sx} {sy} {sz}"/></geometry></collision></link>
  <joint name="{name}_joint" type="continuous"><parent link="base_link"/><child link="{name}"/><origin xyz="{x} {y} {HIP_Z_M}" rpy="0 0 0"/><axis xyz="0 1 0"/></joint>
"#,
            -0.5 * sz
        );
    }
    text + "</robot>\n"
}

fn time_s(k: usize) -> f64 {
    k as f64 / RATE_HZ
}

fn body_position(t: f64) -> [f64; 3] {
    [
        SPEED_M_S * t,
        0.0,
        BODY_HEIGHT_M - BOB_M * (TAU * GAIT_HZ * t).cos(),
    ]
}

fn joint_angle(t: f64, phase: f64) -> f64 {
    TAU * GAIT_HZ * t + phase
}

/// Sand force magnitude on leg `leg` at sample `k` (N): cycles through 0, 1, 2, 3 times the
/// leg's scale.
fn force_magnitude(leg: usize, k: usize) -> f64 {
    FORCE_SCALE_N * (leg + 1) as f64 * (k % 4) as f64
}

fn header(t: f64, frame: &str) -> Header {
    Header::new(Time::from_secs(t), frame)
}

fn transform(
    parent: &str,
    child: &str,
    t: f64,
    xyz: [f64; 3],
    q: UnitQuaternion<f64>,
) -> TransformStamped {
    TransformStamped {
        header: header(t, parent),
        child_frame_id: child.into(),
        transform: Transform {
            translation: xyz.into(),
            rotation: [q.i, q.j, q.k, q.w].into(),
        },
    }
}

fn leg_rotation(angle: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_axis_angle(&Vec3::y_axis(), angle)
}

/// Which pose topics the bag gets.
#[derive(Clone, Copy, PartialEq)]
enum PoseTopics {
    /// `/odom`, `/body_pose` and odom→base_link in `/tf`.
    All,
    /// Only odom→base_link in `/tf`.
    TfOnly,
    /// None at all.
    None,
}

#[derive(Clone, Copy)]
struct BagSpec {
    poses: PoseTopics,
    /// Log times are wall time (slower than the stamps) instead of simulated time.
    wall_clock_log: bool,
    /// Sand surface and leg wrenches (false: rigid ground).
    sand: bool,
}

const WALKING: BagSpec = BagSpec {
    poses: PoseTopics::All,
    wall_clock_log: false,
    sand: true,
};

/// Writes the synthetic bag into `dir` and returns the messages written per topic.
fn write_bag(dir: &Path, spec: BagSpec) -> BTreeMap<String, u64> {
    let mut w = BagWriter::create(dir).unwrap();
    let mut counts: BTreeMap<String, u64> = BTreeMap::new();
    let log_ns = |t: f64| -> u64 {
        if spec.wall_clock_log {
            WALL_START_NS + (t * WALL_PER_SIM * NS_PER_S).round() as u64
        } else {
            (t * NS_PER_S).round() as u64
        }
    };
    macro_rules! write {
        ($topic:expr, $t:expr, $msg:expr) => {{
            let topic: &str = $topic;
            w.write(topic, log_ns($t), $msg).unwrap();
            *counts.entry(topic.to_string()).or_default() += 1;
        }};
    }
    w.add_topic("/robot_description", &STRING, Durability::TransientLocal)
        .unwrap();
    write!("/robot_description", 0.0, &StringMsg { data: urdf() });
    w.add_topic("/tf_static", &TF_MESSAGE, Durability::TransientLocal)
        .unwrap();
    write!(
        "/tf_static",
        0.0,
        &TFMessage {
            transforms: vec![transform(
                "base_link",
                "camera",
                0.0,
                [0.07, 0.0, 0.01],
                UnitQuaternion::identity()
            )],
        }
    );
    write!("/gait/frequency", 0.0, &Float64 { data: 1.0 });
    write!(
        "/cmd_vel",
        0.0,
        &Twist {
            linear: [SPEED_M_S, 0.0, 0.0].into(),
            angular: Vector3::default(),
        }
    );
    for k in 0..SAMPLES {
        let t = time_s(k);
        let position = body_position(t);
        write!(
            "/clock",
            t,
            &Clock {
                clock: Time::from_secs(t)
            }
        );
        let pose = Pose {
            position: position.into(),
            orientation: Quaternion::default(),
        };
        if spec.poses == PoseTopics::All {
            write!(
                "/odom",
                t,
                &Odometry {
                    header: header(t, "odom"),
                    child_frame_id: "base_link".into(),
                    pose: PoseWithCovariance {
                        pose,
                        covariance: [0.0; 36],
                    },
                    twist: TwistWithCovariance {
                        twist: Twist {
                            linear: [SPEED_M_S, 0.0, 0.0].into(),
                            angular: Vector3::default(),
                        },
                        covariance: [0.0; 36],
                    },
                }
            );
            write!(
                "/body_pose",
                t,
                &PoseStamped {
                    header: header(t, "odom"),
                    pose,
                }
            );
        }
        let angles: Vec<f64> = LEGS.iter().map(|l| joint_angle(t, l.3)).collect();
        write!(
            "/joint_states",
            t,
            &JointState {
                header: header(t, ""),
                name: LEGS.iter().map(|l| format!("{}_joint", l.0)).collect(),
                position: angles.clone(),
                velocity: vec![TAU * GAIT_HZ; LEGS.len()],
                effort: vec![0.0; LEGS.len()],
            }
        );
        if spec.poses != PoseTopics::None {
            let mut transforms = vec![transform(
                "odom",
                "base_link",
                t,
                position,
                UnitQuaternion::identity(),
            )];
            for ((name, x, y, _), angle) in LEGS.iter().zip(&angles) {
                transforms.push(transform(
                    "base_link",
                    name,
                    t,
                    [*x, *y, HIP_Z_M],
                    leg_rotation(*angle),
                ));
            }
            write!("/tf", t, &TFMessage { transforms });
        }
        if spec.sand {
            for (i, ((name, ..), angle)) in LEGS.iter().zip(&angles).enumerate() {
                // Straight up in odom (the body does not rotate), expressed in the leg frame.
                let up = Vec3::new(0.0, 0.0, force_magnitude(i, k));
                let in_leg = leg_rotation(*angle).inverse() * up;
                write!(
                    &format!("/leg_wrenches/{name}"),
                    t,
                    &WrenchStamped {
                        header: header(t, name),
                        wrench: Wrench {
                            force: [in_leg.x, in_leg.y, in_leg.z].into(),
                            torque: [0.0, 0.01, 0.0].into(),
                        },
                    }
                );
            }
            write!(
                "/body_wrench",
                t,
                &WrenchStamped {
                    header: header(t, "base_link"),
                    wrench: Wrench {
                        force: BODY_FORCE_N.into(),
                        torque: [0.0; 3].into(),
                    },
                }
            );
            if k % (RATE_HZ / SURFACE_RATE_HZ) as usize == 0 {
                let points: Vec<[f32; 3]> = (0..20)
                    .flat_map(|i| (0..10).map(move |j| [0.01 * i as f32, 0.01 * j as f32, 0.0]))
                    .collect();
                write!(
                    "/sand/surface",
                    t,
                    &PointCloud2::from_points(header(t, "odom"), &points)
                );
            }
        }
        if k == SAMPLES / 2 {
            write!("/gait/frequency", t, &Float64 { data: GAIT_HZ });
            write!(
                "/leg_velocity_controller/commands",
                t,
                &Float64MultiArray {
                    layout: MultiArrayLayout::default(),
                    data: vec![TAU * GAIT_HZ; LEGS.len()],
                }
            );
        }
    }
    w.finish().unwrap();
    counts
}

/// The lowest z of a leg box (m) hanging from a hip at `hip_z`, turned by `angle` about y.
fn leg_lowest_z(hip_z: f64, angle: f64) -> f64 {
    let [thickness, _, length] = LEG_SIZE_M;
    let centre_z = hip_z - 0.5 * length * angle.cos();
    centre_z - 0.5 * thickness * angle.sin().abs() - 0.5 * length * angle.cos().abs()
}

/// Mean and max over the samples of the deepest leg point below z = 0 (m).
fn expected_sinkage() -> (f64, f64) {
    let depths: Vec<f64> = (0..SAMPLES)
        .map(|k| {
            let t = time_s(k);
            let hip_z = body_position(t)[2] + HIP_Z_M;
            LEGS.iter()
                .map(|l| (-leg_lowest_z(hip_z, joint_angle(t, l.3))).max(0.0))
                .fold(0.0, f64::max)
        })
        .collect();
    let mean = depths.iter().sum::<f64>() / depths.len() as f64;
    (mean, depths.iter().copied().fold(0.0, f64::max))
}

fn bag_dir(tmp: &tempfile::TempDir) -> PathBuf {
    tmp.path().join("walk")
}

fn assert_near(what: &str, value: f64, expected: f64, tolerance: f64) {
    assert!(
        (value - expected).abs() <= tolerance,
        "{what}: {value} is not within {tolerance} of {expected}"
    );
}

fn analyze(spec: BagSpec) -> (BagAnalysis, BTreeMap<String, u64>) {
    let tmp = tempfile::tempdir().unwrap();
    let dir = bag_dir(&tmp);
    let counts = write_bag(&dir, spec);
    (analyze_bag(&dir).unwrap(), counts)
}

fn assert_walks_at_the_set_speed(a: &BagAnalysis) {
    let s = &a.summary;
    assert_near("duration", s.duration_s, 3.0, 1e-9);
    assert_near("distance", s.distance_m, SPEED_M_S * 3.0, 1e-9);
    assert_near(
        "mean speed",
        s.mean_speed_m_s.unwrap(),
        SPEED_M_S,
        0.01 * SPEED_M_S,
    );
    let cycles = s.gait_cycles.unwrap();
    assert!((5..=7).contains(&cycles), "{cycles} cycles");
    assert_eq!(s.speed_per_cycle_m_s.len(), cycles);
    for v in &s.speed_per_cycle_m_s {
        assert_near("speed per cycle", *v, SPEED_M_S, 0.01 * SPEED_M_S);
    }
    assert_near(
        "per-cycle mean",
        s.speed_per_cycle_mean_m_s.unwrap(),
        SPEED_M_S,
        1e-3 * SPEED_M_S,
    );
    assert!(s.speed_per_cycle_std_m_s.unwrap() < 1e-3 * SPEED_M_S);
}

#[test]
fn walking_bag_summary_matches_the_motion() {
    let (a, counts) = analyze(WALKING);
    let s = &a.summary;
    assert_eq!(s.pose_source, "/odom");
    assert_walks_at_the_set_speed(&a);
    assert_eq!(s.gait_joint.as_deref(), Some("leg_front_left_joint"));
    assert_near("lateral drift", s.lateral_drift_m, 0.0, 1e-12);
    // Six whole bob periods plus one sample at the lowest point.
    assert_near(
        "mean height",
        s.body_height_mean_m,
        BODY_HEIGHT_M,
        BOB_M / SAMPLES as f64 + 1e-12,
    );
    assert_near(
        "min height",
        s.body_height_min_m,
        BODY_HEIGHT_M - BOB_M,
        1e-12,
    );
    assert_near("max tilt", s.max_tilt_deg, 0.0, 1e-9);

    // Sinkage: the legs as built, against the flat surface at z = 0.
    assert_near("sand level", s.sand_level_m.unwrap(), 0.0, 1e-12);
    let (mean, max) = expected_sinkage();
    // Deepest at t = 0: body at its lowest, a tripod straight down.
    assert_near(
        "expected max",
        max,
        LEG_SIZE_M[2] - (BODY_HEIGHT_M - BOB_M + HIP_Z_M),
        1e-12,
    );
    assert_near("sinkage max", s.sinkage_max_m.unwrap(), max, 1e-9);
    assert_near("sinkage mean", s.sinkage_mean_m.unwrap(), mean, 1e-9);

    // Forces: |F| statistics and the vertical component (all of it points up).
    assert_eq!(s.leg_forces.len(), LEGS.len());
    for (i, (name, ..)) in LEGS.iter().enumerate() {
        let f = &s.leg_forces[*name];
        let written: Vec<f64> = (0..SAMPLES).map(|k| force_magnitude(i, k)).collect();
        let mean = written.iter().sum::<f64>() / SAMPLES as f64;
        assert_eq!(f.samples, SAMPLES);
        assert_eq!(f.topic, format!("/leg_wrenches/{name}"));
        assert_near("mean force", f.mean_force_n, mean, 1e-9);
        assert_near(
            "peak force",
            f.peak_force_n,
            3.0 * FORCE_SCALE_N * (i + 1) as f64,
            1e-9,
        );
        assert_near(
            "mean vertical force",
            f.mean_vertical_force_n.unwrap(),
            mean,
            1e-9,
        );
    }
    let body = s.body_force.as_ref().expect("the body's force");
    assert_eq!(
        (body.topic.as_str(), body.samples),
        ("/body_wrench", SAMPLES)
    );
    let magnitude = BODY_FORCE_N.iter().map(|f| f * f).sum::<f64>().sqrt();
    assert_near("body mean force", body.mean_force_n, magnitude, 1e-9);
    assert_near("body peak force", body.peak_force_n, magnitude, 1e-9);
    assert_near(
        "body mean vertical force",
        body.mean_vertical_force_n.unwrap(),
        BODY_FORCE_N[2],
        1e-9,
    );

    // Commands.
    let gait = &s.commands["/gait/frequency"];
    assert_eq!(
        (gait.count, gait.first.as_f64(), gait.last.as_f64()),
        (2, Some(1.0), Some(GAIT_HZ))
    );
    assert_eq!(
        s.commands["/cmd_vel"].first["linear"]["x"].as_f64(),
        Some(SPEED_M_S)
    );
    let leg_commands = &s.commands["/leg_velocity_controller/commands"];
    assert_eq!(leg_commands.last.as_array().unwrap().len(), LEGS.len());

    // Topics: exactly what was written.
    let topics: BTreeMap<String, u64> =
        s.topics.iter().map(|t| (t.name.clone(), t.count)).collect();
    assert_eq!(topics, counts);
    let odom = s.topics.iter().find(|t| t.name == "/odom").unwrap();
    assert_eq!(odom.type_name, "nav_msgs/msg/Odometry");
    assert!(s.notes.is_empty(), "{:?}", s.notes);

    // The series behind the plots.
    assert_eq!(a.series.body_position.len(), SAMPLES);
    assert_eq!(a.series.joint_angles.len(), LEGS.len());
    assert_eq!(a.series.leg_forces.len(), LEGS.len());
    assert_eq!(a.series.speed_window_s, SPEED_WINDOW_S);
    for (_, v) in &a.series.speed {
        assert_near("smoothed speed", *v, SPEED_M_S, 1e-6);
    }
}

#[test]
fn wall_clock_log_times_use_the_header_stamps() {
    let (a, _) = analyze(BagSpec {
        wall_clock_log: true,
        ..WALKING
    });
    assert_walks_at_the_set_speed(&a);
}

#[test]
fn tf_alone_gives_the_body_pose() {
    let (a, _) = analyze(BagSpec {
        poses: PoseTopics::TfOnly,
        ..WALKING
    });
    assert_eq!(a.summary.pose_source, "/tf");
    assert_walks_at_the_set_speed(&a);
    let (_, max) = expected_sinkage();
    assert_near("sinkage max", a.summary.sinkage_max_m.unwrap(), max, 1e-9);
}

#[test]
fn rigid_ground_bag_has_no_sinkage_or_forces_and_skips_that_plot() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = bag_dir(&tmp);
    write_bag(
        &dir,
        BagSpec {
            sand: false,
            ..WALKING
        },
    );
    let a = analyze_bag(&dir).unwrap();
    let s = &a.summary;
    assert_eq!(
        (s.sinkage_mean_m, s.sinkage_max_m, s.sand_level_m),
        (None, None, None)
    );
    assert!(s.leg_forces.is_empty());
    assert!(s.body_force.is_none());
    assert!(
        s.notes.iter().any(|n| n.contains("/sand/surface")),
        "{:?}",
        s.notes
    );
    let json = serde_json::to_value(s).unwrap();
    assert!(json["sinkage_mean_m"].is_null() && json["sinkage_max_m"].is_null());

    let plots = tmp.path().join("plots");
    let written = write_plots(&a, &plots).unwrap();
    assert_eq!(written.files.len(), 6, "three plots, PNG and SVG each");
    assert!(!plots.join("leg_forces.png").exists());
    assert!(
        written.notes.iter().any(|n| n.contains("leg_forces")),
        "{:?}",
        written.notes
    );
}

#[test]
fn a_bare_mcap_file_reads_like_its_bag() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = bag_dir(&tmp);
    write_bag(&dir, WALKING);
    let mcap = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "mcap"))
        .unwrap();
    let from_file = analyze_bag(&mcap).unwrap();
    let from_dir = analyze_bag(&dir).unwrap();
    assert_eq!(from_file.series, from_dir.series);
    assert_eq!(
        from_file.summary.speed_per_cycle_m_s,
        from_dir.summary.speed_per_cycle_m_s
    );
}

#[test]
fn a_bag_without_pose_names_what_it_has_and_needs() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = bag_dir(&tmp);
    write_bag(
        &dir,
        BagSpec {
            poses: PoseTopics::None,
            ..WALKING
        },
    );
    let err = analyze_bag(&dir).unwrap_err().to_string();
    for needed in [
        "/odom",
        "/body_pose",
        "/tf",
        "base_link",
        "/joint_states (sensor_msgs/msg/JointState",
    ] {
        assert!(err.contains(needed), "{needed:?} missing from: {err}");
    }
}

#[test]
fn a_wrongly_typed_topic_names_both_types() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = bag_dir(&tmp);
    let mut w = BagWriter::create(&dir).unwrap();
    let pose = PoseStamped {
        header: header(0.0, "odom"),
        pose: Pose::default(),
    };
    w.write("/odom", 0, &pose).unwrap();
    w.finish().unwrap();
    let err = analyze_bag(&dir).unwrap_err().to_string();
    for part in [
        "/odom",
        "geometry_msgs/msg/PoseStamped",
        "nav_msgs/msg/Odometry",
    ] {
        assert!(err.contains(part), "{part:?} missing from: {err}");
    }
}

fn sandstep(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_sandstep"))
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn cli_prints_json_and_writes_plots() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = bag_dir(&tmp);
    write_bag(&dir, WALKING);
    let plots = tmp.path().join("plots");
    let out = sandstep(&[
        "analyze",
        dir.to_str().unwrap(),
        "--json",
        "--plots",
        plots.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for key in [
        "bag",
        "duration_s",
        "distance_m",
        "mean_speed_m_s",
        "speed_per_cycle_m_s",
        "speed_per_cycle_mean_m_s",
        "speed_per_cycle_std_m_s",
        "gait_cycles",
        "lateral_drift_m",
        "body_height_mean_m",
        "body_height_min_m",
        "max_tilt_deg",
        "sinkage_mean_m",
        "sinkage_max_m",
        "leg_forces",
        "body_force",
        "commands",
        "topics",
    ] {
        assert!(v.get(key).is_some(), "no {key} in {v}");
    }
    assert_near(
        "mean speed",
        v["mean_speed_m_s"].as_f64().unwrap(),
        SPEED_M_S,
        0.01 * SPEED_M_S,
    );
    assert!(v["topics"]
        .as_array()
        .unwrap()
        .iter()
        .any(|t| t["name"] == "/odom"
            && t["type"] == "nav_msgs/msg/Odometry"
            && t["count"] == SAMPLES as u64));
    assert!(
        v["leg_forces"]["leg_front_left"]["peak_force_n"]
            .as_f64()
            .unwrap()
            > 0.0
    );

    for stem in ["trajectory_xy", "speed", "joint_angles", "leg_forces"] {
        let png = std::fs::read(plots.join(format!("{stem}.png"))).unwrap();
        assert!(
            png.starts_with(b"\x89PNG\r\n\x1a\n") && png.len() > 1000,
            "{stem}.png"
        );
        let svg = std::fs::read_to_string(plots.join(format!("{stem}.svg"))).unwrap();
        assert!(
            svg.contains("<svg") && svg.contains("time (s)") || stem == "trajectory_xy",
            "{stem}.svg"
        );
    }
    assert_eq!(v["plots"].as_array().unwrap().len(), 8);

    let human = sandstep(&["analyze", dir.to_str().unwrap()]);
    assert!(human.status.success());
    let text = String::from_utf8(human.stdout).unwrap();
    assert!(text.contains("mean speed 0.1000 m/s"), "{text}");
}

#[test]
fn a_window_covers_the_time_from_its_start_and_its_first_cycles() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = bag_dir(&tmp);
    write_bag(&dir, WALKING);
    let whole = analyze_bag(&dir).unwrap();
    let opts = AnalysisOptions {
        start_s: 1.2,
        max_cycles: Some(2),
    };
    let a = analyze_bag_with(&dir, &opts).unwrap();
    let s = &a.summary;
    assert_eq!(s.start_s, 1.2);
    assert_near("duration", s.duration_s, 1.8, 1e-9);
    assert_near("distance", s.distance_m, SPEED_M_S * 1.8, 1e-9);
    assert_near("mean speed", s.mean_speed_m_s.unwrap(), SPEED_M_S, 1e-9);
    // The joint turns at 2 Hz from angle 0: the first cycles from 1.2 s start at 1.5 and 2 s.
    assert_eq!(s.gait_cycles, Some(2));
    assert_near("first cycle", a.series.cycles[0].start_s, 1.5, 1e-9);
    assert_near("second cycle", a.series.cycles[1].start_s, 2.0, 1e-9);
    assert_near(
        "per-cycle mean",
        s.speed_per_cycle_mean_m_s.unwrap(),
        SPEED_M_S,
        1e-3 * SPEED_M_S,
    );
    // Forces and sinkage over the window only; the plots' series over the whole bag.
    let samples = |a: &BagAnalysis| a.summary.leg_forces["leg_front_left"].samples;
    assert!(samples(&a) < samples(&whole) && samples(&a) > 0);
    assert!(s.sinkage_mean_m.is_some());
    assert_eq!(a.series.body_position, whole.series.body_position);

    let late = AnalysisOptions {
        start_s: 3.5,
        max_cycles: None,
    };
    let err = analyze_bag_with(&dir, &late).unwrap_err().to_string();
    assert!(
        err.contains("cannot start at 3.5 s: the body poses cover 0 to 3 s"),
        "{err}"
    );

    let out = sandstep(&["analyze", dir.to_str().unwrap(), "--start", "1.2", "--json"]);
    assert!(out.status.success());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["start_s"], 1.2);
    assert_eq!(v["gait_cycles"], 3, "the cycles from 1.5, 2 and 2.5 s");
}

#[test]
fn cli_error_names_the_missing_pose() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = bag_dir(&tmp);
    write_bag(
        &dir,
        BagSpec {
            poses: PoseTopics::None,
            ..WALKING
        },
    );
    let out = sandstep(&["analyze", dir.to_str().unwrap(), "--json"]);
    assert!(!out.status.success());
    assert!(out.stdout.is_empty());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("no body pose") && stderr.contains("/odom"),
        "{stderr}"
    );
}
