//! The command line: `run --json` and `bench --json` print the documented keys.

use std::process::Command;

fn sandstep(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_sandstep"))
        .args(args)
        .output()
        .unwrap()
}

/// Runs a command that must succeed and print one JSON object.
fn sandstep_json(args: &[&str]) -> serde_json::Value {
    let out = sandstep(args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn run_json_has_the_documented_keys() {
    let v = sandstep_json(&[
        "run",
        "config/column_collapse.yaml",
        "--duration",
        "0.02",
        "--threads",
        "2",
        "--json",
        "--no-bag",
    ]);
    for key in [
        "scene",
        "steps",
        "sim_time_s",
        "wall_time_s",
        "particles",
        "particle_steps_per_s",
    ] {
        assert!(v.get(key).is_some(), "missing {key} in {v}");
    }
    assert!((v["sim_time_s"].as_f64().unwrap() - 0.02).abs() < 1e-6);
    let m = &v["metrics"];
    for key in [
        "initial_length_m",
        "initial_height_m",
        "runout_m",
        "final_height_m",
        "normalized_runout",
    ] {
        assert!(m[key].as_f64().unwrap().is_finite(), "metric {key} in {m}");
    }
    assert!((m["initial_length_m"].as_f64().unwrap() - 0.048).abs() < 1e-4);
}

#[test]
fn bench_json_has_the_documented_keys() {
    let v = sandstep_json(&[
        "bench",
        "--particles",
        "4000",
        "--steps",
        "3",
        "--threads",
        "1",
        "--json",
    ]);
    assert!(v["particles"].as_u64().unwrap() > 3000);
    assert_eq!(v["threads"].as_u64(), Some(1));
    assert!(v["particle_steps_per_s"].as_f64().unwrap() > 0.0);
    for stage in ["sort", "grid_alloc", "p2g", "grid_update", "g2p"] {
        assert!(
            v["stages"][stage].as_f64().is_some(),
            "stage {stage} in {v}"
        );
    }
}

#[test]
fn bad_scene_fails_with_the_file_and_field() {
    let out = sandstep(&[
        "run",
        "config/column_collapse.yaml",
        "--set",
        "sand.dx_m=-1",
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("config/column_collapse.yaml") && err.contains("sand.dx_m"),
        "{err}"
    );
}

#[test]
fn run_records_a_bag_of_the_robot() {
    let dir = tempfile::tempdir().unwrap();
    let bag = dir.path().join("ground");
    let v = sandstep_json(&[
        "run",
        "config/robot_on_ground.yaml",
        "--duration",
        "1",
        "--json",
        "--bag",
        bag.to_str().unwrap(),
    ]);
    let reader = sandstep::bag::BagReader::open(&bag).unwrap();
    let count = |topic: &str| {
        reader
            .topics()
            .iter()
            .find(|t| t.name == topic)
            .map_or(0, |t| t.message_count)
    };
    // 100 Hz of sim time for 1 s, both ends included.
    for topic in ["/clock", "/odom", "/joint_states", "/tf", "/body_pose"] {
        assert_eq!(count(topic), 101, "{topic}: {:?}", reader.topics());
    }
    assert_eq!(count("/robot_description"), 1);
    assert_eq!(count("/tf_static"), 1);
    // The bag's last pose is the run's final position.
    let odom: Vec<(u64, sandstep::msgs::Odometry)> = reader.read("/odom").unwrap();
    let (t_ns, last) = odom.last().unwrap();
    assert_eq!(*t_ns, 1_000_000_000);
    let final_x = v["metrics"]["final_position_m"][0].as_f64().unwrap();
    assert!(
        (last.pose.pose.position.x - final_x).abs() < 1e-9,
        "{final_x} vs {last:?}"
    );
}

#[test]
fn run_refuses_an_existing_bag_directory() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("something"), "x").unwrap();
    let out = sandstep(&[
        "run",
        "config/robot_on_ground.yaml",
        "--duration",
        "0.1",
        "--bag",
        dir.path().to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains(dir.path().to_str().unwrap()), "{err}");
}

#[test]
fn sigterm_stops_a_run_with_its_summary_and_bag() {
    let dir = tempfile::tempdir().unwrap();
    let bag = dir.path().join("terminated");
    let child = Command::new(env!("CARGO_BIN_EXE_sandstep"))
        .args([
            "run",
            "config/robot_on_ground.yaml",
            "--duration",
            "600",
            "--json",
        ])
        .arg("--bag")
        .arg(&bag)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_secs(2));
    let status = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let out = child.wait_with_output().unwrap();
    // Stopped by SIGTERM with its outputs finished: 128 + 15 (tests/stop.rs has the rest).
    assert_eq!(
        out.status.code(),
        Some(143),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["stopped_early"], true, "{v}");
    let sim_time = v["sim_time_s"].as_f64().unwrap();
    assert!(sim_time > 0.0 && sim_time < 600.0, "{v}");
    let reader = sandstep::bag::BagReader::open(&bag).unwrap();
    let odom = reader
        .topics()
        .iter()
        .find(|t| t.name == "/odom")
        .unwrap()
        .message_count;
    // One pose per 0.01 s, the start included (the run stops within a frame, after a substep).
    assert_eq!(odom, (sim_time * 100.0 + 1e-6).floor() as u64 + 1, "{v}");
    assert!(reader.metadata_counts().is_some(), "metadata.yaml written");
}

/// A scene that cannot be read is told once why (issue 22: a directory repeated "Is a
/// directory (os error 21)" twice), with the file named and a failing exit code.
#[test]
fn an_unreadable_scene_is_told_once() {
    for scene in ["config", "config/no_such_scene.yaml"] {
        let out = sandstep(&["run", scene, "--no-bag"]);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{scene}: {stderr}");
        assert!(stderr.contains(scene), "{scene}: {stderr}");
        assert_eq!(stderr.matches("os error").count(), 1, "{scene}: {stderr}");
    }
}

/// A grid too fine for the machine is refused before anything is allocated, naming the
/// spacing, the domain and the figure (before 2026-12-06 it aborted inside an allocation of
/// 45 TB, exit 134).
#[test]
fn a_grid_that_does_not_fit_is_refused_before_allocating() {
    let out = sandstep(&[
        "run",
        "config/robot_on_sand.yaml",
        "--no-bag",
        "--set",
        "sand.dx_m=1e-6",
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    for part in [
        "sand.dx_m = 0.000001 m",
        "sand.domain",
        "GB",
        "available memory",
    ] {
        assert!(stderr.contains(part), "`{part}` in {stderr}");
    }
}

/// `--max-memory` holds the sand to a limit: the default scene's bed (106 k particles, about
/// 50 MB) does not fit in 10 MB; a limit that is not a positive number is refused.
#[test]
fn max_memory_limits_the_sand() {
    let out = sandstep(&[
        "run",
        "config/robot_on_sand.yaml",
        "--no-bag",
        "--max-memory",
        "0.01",
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    for part in ["sand.dx_m = 0.01 m", "the --max-memory limit (0.010 GB)"] {
        assert!(stderr.contains(part), "`{part}` in {stderr}");
    }
    for bad in ["0", "-1", "nan"] {
        let limit = format!("--max-memory={bad}");
        let out = sandstep(&["run", "config/robot_on_sand.yaml", "--no-bag", &limit]);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && stderr.contains("--max-memory"),
            "{bad}: {stderr}"
        );
    }
}
