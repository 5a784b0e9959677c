//! Studies as independent jobs (`docs/cluster.md`): an experiment's runs and a sweep's settings
//! run as shards in separate processes into one folder, then merged, give the results of a
//! single process; the Slurm scripts in `docs/cluster/` do the same when given the
//! environment Slurm gives an array task. All on RFT ground (seconds), whose runs are
//! deterministic, so "the same results" means the same numbers.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};

use serde_json::Value;

/// Three curvatures, two starts: six runs of 1 s.
const EXPERIMENT: &str = "name: shards\ncurvatures_per_r: [-1, 0.5, 1]\nfrequencies_hz: [2]\n\
    terrain_models: [rft]\nsettle_s: 0\ncycles: 1\nstarts: 2\nstart_spacing_m: 0.01\n";

/// A reference and two settings, two starts each: the merge must score them against it.
const SWEEP: &str = r#"
name: shards
studies:
  - name: robot_rft
    base_scene: config/robot_on_sand.yaml
    overrides: [terrain.model=rft, terrain.rft.zeta_n_m3=3.0e5]
    quantity: robot_speed
    reference: [terrain.rft.max_dt_s=0.00025]
    cycles: 1
    starts: 2
    vary:
      - key: terrain.rft.max_dt_s
        values: [0.001, 0.004]
"#;

fn sandstep() -> Command {
    Command::new(env!("CARGO_BIN_EXE_sandstep"))
}

/// `sandstep <command> --json --out <out> <extra...> <file>`: its output.
fn study(command: &str, file: &Path, out: &Path, extra: &[&str]) -> Output {
    sandstep()
        .args([command, "--json", "--out"])
        .arg(out)
        .args(extra)
        .arg(file)
        .output()
        .unwrap()
}

/// `output`'s stdout as JSON, after checking it succeeded.
fn json_of(output: Output) -> Value {
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stderr}");
    serde_json::from_slice(&output.stdout).unwrap_or_else(|e| panic!("{e}: {stderr}"))
}

/// Starts `command` with stdout captured.
fn spawn(command: &mut Command) -> Child {
    command
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// A result row without what differs between processes and folders: wall times, the Pareto
/// front a sweep draws from them (cost is wall time), and paths.
fn physics(row: &Value) -> Value {
    let mut row = row.clone();
    for key in [
        "wall_time_s",
        "wall_time_per_sim_s",
        "pareto_optimal",
        "bag",
        "urdf",
    ] {
        row.as_object_mut().unwrap().remove(key);
    }
    row
}

/// `study file --list`, one name per line.
fn list(command: &str, file: &Path) -> Vec<String> {
    let output = sandstep()
        .args([command])
        .arg(file)
        .arg("--list")
        .output()
        .unwrap();
    assert!(output.status.success());
    String::from_utf8(output.stdout)
        .unwrap()
        .lines()
        .map(String::from)
        .collect()
}

#[test]
fn experiment_shards_in_two_processes_merge_to_the_single_run() {
    let tmp = tempfile::tempdir().unwrap();
    let file = tmp.path().join("shards.yaml");
    std::fs::write(&file, EXPERIMENT).unwrap();
    let names = list("experiment", &file);
    assert_eq!(
        names,
        [
            "k-1_f2hz_rft_start0",
            "k-1_f2hz_rft_start1",
            "k0.5_f2hz_rft_start0"
        ]
        .into_iter()
        .chain([
            "k0.5_f2hz_rft_start1",
            "k1_f2hz_rft_start0",
            "k1_f2hz_rft_start1"
        ])
        .collect::<Vec<_>>()
    );

    let single = json_of(study("experiment", &file, &tmp.path().join("single"), &[]));

    let shared = tmp.path().join("shared");
    let shard = |i: usize, extra: &[&str]| {
        spawn(
            sandstep()
                .args(["experiment", "--json", "--threads", "1", "--out"])
                .arg(&shared)
                .args(["--shard", &format!("{i}/3")])
                .args(extra)
                .arg(&file),
        )
    };
    let merge = || study("experiment", &file, &shared, &["--merge"]);
    let run_names = |report: &Value| -> Vec<String> {
        report["runs"]
            .as_array()
            .unwrap()
            .iter()
            .map(|r| r["run"].as_str().unwrap().to_string())
            .collect()
    };
    let held_by = |i: usize| vec![names[i - 1].clone(), names[i + 2].clone()];
    // Two shards at once into one folder; each holds every third run, and neither writes the
    // results of the whole experiment.
    let (one, two) = (shard(1, &[]), shard(2, &[]));
    let first = json_of(one.wait_with_output().unwrap());
    let second = json_of(two.wait_with_output().unwrap());
    assert_eq!(run_names(&first), held_by(1));
    assert_eq!(run_names(&second), held_by(2));
    assert!(!shared.join("results.json").exists());
    // Merging before the third shard ran names what is missing.
    let early = merge();
    let stderr = String::from_utf8_lossy(&early.stderr);
    assert!(!early.status.success());
    assert!(
        stderr.contains("2 of 6 runs have no result") && stderr.contains(&names[2]),
        "{stderr}"
    );

    // Run again, a shard refuses its earlier bags before running or writing anything ...
    let records = shared.join("runs");
    let listing = || {
        let mut files: Vec<_> = std::fs::read_dir(&records)
            .unwrap()
            .map(|e| {
                let e = e.unwrap();
                (e.file_name(), e.metadata().unwrap().modified().unwrap())
            })
            .collect();
        files.sort();
        files
    };
    let before = listing();
    let refused = shard(1, &[]).wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success());
    assert!(
        stderr.contains("earlier attempt") && stderr.contains("--resume"),
        "{stderr}"
    );
    assert_eq!(listing(), before, "the refused shard wrote nothing");
    // ... and with --resume keeps what it finished (here all of it), while the third shard
    // runs beside it, as the tasks of a requeued array do.
    let (third, again) = (shard(3, &[]), shard(1, &["--resume"]));
    let third = json_of(third.wait_with_output().unwrap());
    let again = json_of(again.wait_with_output().unwrap());
    assert_eq!(again["runs"], first["runs"], "kept as they were");
    assert_eq!(run_names(&third), held_by(3));

    let merged = json_of(merge());
    assert_eq!(merged["failed"], 0);
    assert_eq!(run_names(&merged), names);
    let single_runs = single["runs"].as_array().unwrap();
    let merged_runs = merged["runs"].as_array().unwrap();
    for (one, many) in single_runs.iter().zip(merged_runs) {
        assert_eq!(physics(one), physics(many), "RFT runs are deterministic");
    }
    assert_eq!(merged["cells"], single["cells"]);
    assert_eq!(merged["config"], single["config"]);
    for file in [
        "results.csv",
        "summary.csv",
        "results.json",
        "speed_vs_curvature.png",
    ] {
        assert!(shared.join(file).is_file(), "{file}");
    }
    assert_eq!(
        std::fs::read_to_string(shared.join("summary.csv")).unwrap(),
        std::fs::read_to_string(tmp.path().join("single/summary.csv")).unwrap()
    );

    // One process resuming the shards' folder keeps every run and writes the same results.
    let resumed = json_of(study("experiment", &file, &shared, &["--resume"]));
    assert_eq!(resumed["runs"], merged["runs"]);
    assert_eq!(resumed["cells"], merged["cells"]);

    // A merge with other settings than the shards' is refused, naming a record and the
    // setting that differs.
    let other = study(
        "experiment",
        &file,
        &shared,
        &["--merge", "--set", "cycles=2"],
    );
    let stderr = String::from_utf8_lossy(&other.stderr);
    assert!(!other.status.success());
    assert!(
        stderr.contains("holds a result of other settings (cycles: recorded 1, now 2)"),
        "{stderr}"
    );
}

#[test]
fn sweep_settings_run_by_name_in_two_processes_merge_to_the_single_run() {
    let tmp = tempfile::tempdir().unwrap();
    let file = tmp.path().join("sweep.yaml");
    std::fs::write(&file, SWEEP).unwrap();
    let labels = list("sweep", &file);
    let expected = ["reference", "baseline", "max_dt_s=0.001", "max_dt_s=0.004"]
        .map(|s| format!("robot_rft/{s}"));
    assert_eq!(labels, expected);

    let single = json_of(study("sweep", &file, &tmp.path().join("single"), &[]));
    let shared = tmp.path().join("shared");
    let by_name = |names: &[&String]| {
        let mut command = sandstep();
        command
            .args(["sweep", "--json", "--threads", "1", "--out"])
            .arg(&shared);
        for name in names {
            command.args(["--run", name]);
        }
        spawn(command.arg(&file))
    };
    // The reference in one process, the settings scored against it in the other.
    let (a, b) = (
        by_name(&[&labels[0]]),
        by_name(&[&labels[3], &labels[1], &labels[2]]),
    );
    let a = json_of(a.wait_with_output().unwrap());
    json_of(b.wait_with_output().unwrap());
    assert_eq!(a["results"].as_array().unwrap().len(), 1);
    let merged = json_of(study("sweep", &file, &shared, &["--merge"]));
    let rows = |report: &Value| -> Vec<Value> {
        report["results"]
            .as_array()
            .unwrap()
            .iter()
            .map(physics)
            .collect()
    };
    assert_eq!(rows(&merged), rows(&single));
    // The scores need the reference from the other process: they are there.
    let baseline = &merged["results"][1];
    assert!(baseline["relative_error"].as_f64().is_some(), "{baseline}");
    assert!(shared.join("robot_rft.png").is_file());

    // An unknown name is refused before anything runs.
    let unknown = study(
        "sweep",
        &file,
        &tmp.path().join("unknown"),
        &["--run", "robot_rft/nothing"],
    );
    let stderr = String::from_utf8_lossy(&unknown.stderr);
    assert!(!unknown.status.success());
    assert!(
        stderr.contains("--run robot_rft/nothing: there is no such run"),
        "{stderr}"
    );
}

/// `docs/cluster/<script>` run by bash with the environment Slurm gives it.
fn slurm_job(script: &str, env: &[(&str, String)]) -> Output {
    let mut command = Command::new("bash");
    command.arg(Path::new("docs/cluster").join(script));
    command.env("SANDSTEP", env!("CARGO_BIN_EXE_sandstep"));
    for (key, value) in env {
        command.env(key, value);
    }
    command.output().unwrap()
}

/// Runs `study.sbatch` as the tasks 1..=`shards` of an array and then `merge.sbatch`, for
/// the study `command` in `file`; returns the merged report.
fn slurm_array(command: &str, file: &Path, out: &Path, args: &str, shards: usize) -> Value {
    let study = [
        ("SANDSTEP_COMMAND", command.to_string()),
        ("SANDSTEP_FILE", file.display().to_string()),
        ("SANDSTEP_OUT", out.display().to_string()),
        ("SANDSTEP_ARGS", args.to_string()),
        ("SANDSTEP_SHARDS", shards.to_string()),
    ];
    // The report's rows: an experiment's runs, a sweep's settings.
    let rows = if command == "sweep" {
        "results"
    } else {
        "runs"
    };
    let count = |report: &Value| report[rows].as_array().unwrap().len();
    let mut ran = 0;
    for id in 1..=shards {
        let mut env = study.to_vec();
        env.extend([
            ("SLURM_ARRAY_TASK_ID", id.to_string()),
            ("SLURM_CPUS_PER_TASK", "1".to_string()),
        ]);
        ran += count(&json_of(slurm_job("study.sbatch", &env)));
    }
    let merged = json_of(slurm_job("merge.sbatch", &study));
    assert_eq!(
        ran,
        count(&merged),
        "every {command} run in exactly one task"
    );
    assert_eq!(merged["failed"], 0);
    assert!(out.join("results.csv").is_file());
    merged
}

#[test]
fn the_slurm_scripts_run_the_shards_and_the_merge() {
    let tmp = tempfile::tempdir().unwrap();
    let file = tmp.path().join("shards.yaml");
    std::fs::write(&file, EXPERIMENT).unwrap();
    let out: PathBuf = tmp.path().join("out");
    let merged = slurm_array("experiment", &file, &out, "--json --set cycles=1", 4);
    assert_eq!(merged["runs"].as_array().unwrap().len(), 6);
    // A sweep: no --resume is added, and the tasks run under `set -u` with nothing extra.
    let sweep = tmp.path().join("sweep.yaml");
    std::fs::write(&sweep, SWEEP).unwrap();
    let merged = slurm_array("sweep", &sweep, &tmp.path().join("sweep"), "--json", 3);
    assert_eq!(merged["results"].as_array().unwrap().len(), 4);

    // Outside an array the task script says what it needs; an id beyond the shards is refused.
    let env = |id: Option<&str>| {
        let mut env = vec![
            ("SANDSTEP_COMMAND", "experiment".to_string()),
            ("SANDSTEP_FILE", file.display().to_string()),
            ("SANDSTEP_OUT", out.display().to_string()),
            ("SANDSTEP_SHARDS", "4".to_string()),
        ];
        env.extend(id.map(|id| ("SLURM_ARRAY_TASK_ID", id.to_string())));
        env
    };
    let lone = slurm_job("study.sbatch", &env(None));
    assert!(!lone.status.success());
    assert!(String::from_utf8_lossy(&lone.stderr).contains("job array"));
    let beyond = slurm_job("study.sbatch", &env(Some("0")));
    let stderr = String::from_utf8_lossy(&beyond.stderr);
    assert!(!beyond.status.success());
    assert!(stderr.contains("'0/4': a shard is I/N"), "{stderr}");
}

#[test]
fn submit_sizes_the_array_from_the_list_and_holds_the_merge_until_it_is_over() {
    let tmp = tempfile::tempdir().unwrap();
    let file = tmp.path().join("shards.yaml");
    std::fs::write(&file, EXPERIMENT).unwrap();
    // A stand-in sbatch: logs its arguments and answers with a job id as --parsable does.
    let bin = tmp.path().join("bin");
    std::fs::create_dir(&bin).unwrap();
    let log = tmp.path().join("sbatch.log");
    let sbatch = bin.join("sbatch");
    std::fs::write(
        &sbatch,
        format!(
            "#!/bin/bash\necho \"SANDSTEP_SHARDS=$SANDSTEP_SHARDS $*\" >> '{}'\n\
             echo $((41 + $(wc -l < '{}')))\n",
            log.display(),
            log.display()
        ),
    )
    .unwrap();
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&sbatch, std::fs::Permissions::from_mode(0o755)).unwrap();
    }
    let path = format!("{}:{}", bin.display(), std::env::var("PATH").unwrap());
    let run_submit = |max_tasks: &str| {
        std::fs::remove_file(&log).ok();
        Command::new("bash")
            .arg("docs/cluster/submit.sh")
            .args(["experiment", file.to_str().unwrap()])
            .arg(tmp.path().join("out"))
            .env("PATH", &path)
            .env("SANDSTEP", env!("CARGO_BIN_EXE_sandstep"))
            .env("SANDSTEP_MAX_TASKS", max_tasks)
            .output()
            .unwrap()
    };
    let submit = |max_tasks: &str| {
        let output = run_submit(max_tasks);
        assert!(
            output.status.success(),
            "{}",
            String::from_utf8_lossy(&output.stderr)
        );
        let calls = std::fs::read_to_string(&log).unwrap();
        let calls: Vec<String> = calls.lines().map(String::from).collect();
        (String::from_utf8(output.stdout).unwrap(), calls)
    };
    let (said, calls) = submit("64");
    assert_eq!(calls.len(), 2, "{calls:?}");
    assert!(calls[0].contains("--array=1-6") && calls[0].ends_with("study.sbatch"));
    assert!(
        calls[0].starts_with("SANDSTEP_SHARDS=6 --parsable --export=ALL"),
        "{calls:?}"
    );
    assert!(calls[1].contains("--dependency=afterany:42") && calls[1].ends_with("merge.sbatch"));
    assert!(
        said.starts_with("6 runs in 6 array tasks: job 42; merge: job 43"),
        "{said}"
    );
    // Fewer tasks than runs: each task runs several.
    let (_, calls) = submit("4");
    assert!(calls[0].starts_with("SANDSTEP_SHARDS=4 "), "{calls:?}");
    assert!(calls[0].contains("--array=1-4"), "{calls:?}");
    // No tasks: refused before anything is submitted.
    let none = run_submit("0");
    assert!(!none.status.success());
    assert!(String::from_utf8_lossy(&none.stderr).contains("nothing to submit"));
    assert!(!log.exists());
}
