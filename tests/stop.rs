//! Stopping a run: SIGTERM and Ctrl-C (SIGINT) are honoured inside a frame (the stop request is
//! polled every substep and inside substeps, not between frames), the bag is finished, the
//! summary says where the run stopped, and the exit code is 128 plus the signal (143, 130).
//! Output into a closed pipe ends the process quietly instead of panicking.

use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use sandstep::bag::BagReader;

/// Simulated time the interrupted runs are asked for (s): far more than they get.
const LONG_RUN_S: &str = "100";
/// One frame for the whole run (s): before 2026-12-06 a stop request waited for the frame's
/// end, so these runs would not have stopped.
const ONE_LONG_FRAME_S: &str = "output.frame_interval_s=50";
/// How long a stopped run may take to finish its outputs before the test gives up (s): a
/// hang guard, generous for a loaded machine, not a measure of speed.
const FINISH_TIMEOUT_S: u64 = 120;

/// Starts `sandstep run` on the robot scene at a coarse grid, recording into `bag`.
fn start_run(bag: &Path, json: bool) -> Child {
    let mut args = vec![
        "run",
        "config/robot_on_sand.yaml",
        "--threads",
        "2",
        "--duration",
        LONG_RUN_S,
        "--set",
        "sand.dx_m=0.0125",
        "--set",
        ONE_LONG_FRAME_S,
        "--bag",
        bag.to_str().unwrap(),
    ];
    if json {
        args.push("--json");
    }
    Command::new(env!("CARGO_BIN_EXE_sandstep"))
        .args(&args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// Waits until the run is stepping (its bag's MCAP exists, then a second more), then sends
/// `signal` (`-TERM`, `-INT`).
fn signal_when_running(child: &Child, bag: &Path, signal: &str) {
    let deadline = Instant::now() + Duration::from_secs(FINISH_TIMEOUT_S);
    let mcap = bag.join(format!(
        "{}_0.mcap",
        bag.file_name().unwrap().to_str().unwrap()
    ));
    while !mcap.exists() {
        assert!(Instant::now() < deadline, "no bag at {}", mcap.display());
        std::thread::sleep(Duration::from_millis(50));
    }
    std::thread::sleep(Duration::from_secs(1));
    let status = Command::new("kill")
        .args([signal, &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
}

/// Waits for `child` to exit (killing it and failing after [`FINISH_TIMEOUT_S`]).
fn finish(mut child: Child) -> (i32, String, String) {
    let deadline = Instant::now() + Duration::from_secs(FINISH_TIMEOUT_S);
    while child.try_wait().unwrap().is_none() {
        if Instant::now() > deadline {
            child.kill().ok();
            panic!("the run did not stop within {FINISH_TIMEOUT_S} s of the signal");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let out = child.wait_with_output().unwrap();
    (
        out.status.code().expect("exited, not killed"),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// The bag of a stopped run is finished: `metadata.yaml` agrees with the MCAP, and the robot's
/// state was recorded up to where it stopped.
fn assert_finished_bag(bag: &Path) -> usize {
    let reader = BagReader::open(bag).unwrap();
    let counts = reader.metadata_counts().expect("metadata.yaml written");
    let odom = counts
        .iter()
        .find(|(topic, _)| topic == "/odom")
        .map_or(0, |(_, n)| *n);
    assert!(odom >= 2, "odometry recorded: {counts:?}");
    odom as usize
}

#[test]
fn sigterm_inside_a_frame_stops_the_run_and_finishes_its_bag() {
    let dir = tempfile::tempdir().unwrap();
    let bag = dir.path().join("stopped");
    let child = start_run(&bag, true);
    signal_when_running(&child, &bag, "-TERM");
    let (code, stdout, stderr) = finish(child);
    assert_eq!(code, 143, "128 + SIGTERM:\n{stderr}");
    let summary: serde_json::Value = serde_json::from_str(&stdout)
        .unwrap_or_else(|e| panic!("one JSON summary ({e}):\n{stdout}\n{stderr}"));
    assert_eq!(summary["stopped_early"], true, "{summary}");
    let stopped_at = summary["sim_time_s"].as_f64().unwrap();
    assert!(
        stopped_at > 0.0 && stopped_at < 50.0,
        "stopped inside the first frame: t = {stopped_at} s"
    );
    assert_finished_bag(&bag);
    assert!(stderr.contains("SIGTERM: stopping"), "{stderr}");
}

#[test]
fn ctrl_c_is_told_in_the_text_summary() {
    let dir = tempfile::tempdir().unwrap();
    let bag = dir.path().join("interrupted");
    let child = start_run(&bag, false);
    signal_when_running(&child, &bag, "-INT");
    let (code, stdout, stderr) = finish(child);
    assert_eq!(code, 130, "128 + SIGINT:\n{stderr}");
    let line = stdout
        .lines()
        .find(|l| l.contains("stopped early"))
        .unwrap_or_else(|| panic!("the summary says it stopped:\n{stdout}"));
    assert!(
        line.contains("by SIGINT at t = ") && line.contains(&format!("of {LONG_RUN_S} s")),
        "{line}"
    );
    assert_finished_bag(&bag);
}

/// `sandstep analyze bag | head`, the reader gone: the command ends without a panic (before,
/// printing into the closed pipe panicked with a backtrace).
#[test]
fn a_closed_pipe_ends_analyze_quietly() {
    let dir = tempfile::tempdir().unwrap();
    let bag = dir.path().join("short");
    let run = Command::new(env!("CARGO_BIN_EXE_sandstep"))
        .args(["run", "config/robot_on_ground.yaml", "--duration", "0.2"])
        .args(["--bag", bag.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(run.status.success(), "{run:?}");
    let mut child = Command::new(env!("CARGO_BIN_EXE_sandstep"))
        .args(["analyze", bag.to_str().unwrap()])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The pipe's read end closed before analyze has read the bag: its first line meets it.
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
}

/// A stop requested while the scene is being built (a large bed takes seconds to fill) ends the
/// build between its stages, before the sand is filled, and leaves no bag: until 2026-12-06
/// the request was first looked at after the whole build, and the recorder built the scene
/// twice.
#[test]
fn a_stop_while_loading_ends_the_build_before_the_fill() {
    use std::sync::atomic::AtomicBool;
    use std::sync::Arc;

    use sandstep::ros::{record_run, RecordError};
    use sandstep::scene::{NoObserver, RunError, RunOptions, Scene};

    let scene = Scene::load(Path::new("config/robot_on_sand.yaml"), &[]).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let bag = dir.path().join("stopped_while_loading");
    let opts = RunOptions {
        stop: Some(Arc::new(AtomicBool::new(true))),
        ..Default::default()
    };
    let Err(error) = record_run(&scene, &opts, Some(&bag), &mut NoObserver) else {
        panic!("the stop ends the build");
    };
    let RecordError::Run { cause, .. } = &error else {
        panic!("a build error, not {error}");
    };
    assert!(
        matches!(**cause, RunError::StoppedLoading(_)),
        "stopped while loading: {error}"
    );
    assert!(
        error.to_string().contains("nothing was simulated"),
        "{error}"
    );
    assert!(!bag.exists(), "no bag for a run that never started");
}
