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
