//! The same bits on every machine (`docs/determinism.md`).
//!
//! - **Golden runs**: short runs of the shipped scenes whose state digest (SHA-256 of every
//!   particle's and body's bits) and metrics are pinned in `tests/golden/pins.json`. Any change
//!   of numbers shows here at once; re-pin deliberately with
//!   `SANDSTEP_UPDATE_GOLDEN=1 cargo test --release --test determinism golden` and say why in
//!   the commit.
//! - **Code paths**: one coupled robot-on-sand run gives the same digest on 1, 2 and 3 threads,
//!   with glibc's CPU-specific variants masked, and on emulated CPUs (qemu user mode: a CPU
//!   without AVX, and one with AVX2 and FMA but without AVX-512), which is what another machine
//!   would run; and with every SIMD instruction set this CPU has forced (`SANDSTEP_SIMD`).

use std::path::Path;
use std::process::Command;

use serde_json::{json, Map, Value};

/// Where the golden pins live (relative to the crate root).
const PINS: &str = "tests/golden/pins.json";

/// A short run of a shipped scene.
struct Case {
    name: &'static str,
    scene: &'static str,
    duration_s: f64,
    overrides: &'static [&'static str],
}

/// The golden runs. The robot on sand is the default scene's first 0.1 s as shipped.
const GOLDEN: [Case; 4] = [
    Case {
        name: "robot_on_sand_0.1s",
        scene: "config/robot_on_sand.yaml",
        duration_s: 0.1,
        overrides: &[],
    },
    Case {
        name: "column_collapse_a1_0.3s",
        scene: "config/column_collapse.yaml",
        duration_s: 0.3,
        overrides: &[],
    },
    Case {
        name: "robot_on_rft_2s",
        scene: "config/robot_on_sand.yaml",
        duration_s: 2.0,
        overrides: &["terrain.model=rft"],
    },
    Case {
        name: "robot_on_ground_1s",
        scene: "config/robot_on_ground.yaml",
        duration_s: 1.0,
        overrides: &[],
    },
];

/// The coupled run of the code-path checks: the robot on a cropped 1.25 cm bed for 0.04 s
/// (about 19 k particles, 144 substeps at the shipped CFL 0.8; with the shipped sleep settings
/// 110 blocks fall asleep in it): sand, SVD, CPIC, sleeping sand, rapier's multibody and the
/// gait all run, and under emulation it takes about a minute.
const PATHS: Case = Case {
    name: "robot_on_small_bed",
    scene: "config/robot_on_sand.yaml",
    duration_s: 0.04,
    overrides: &[
        "sand.dx_m=0.0125",
        "sand.domain.max_m=[0.2, 0.12, 0.06]",
        "sand.bodies.0.box.max_m=[0.2, 0.12, 0.0]",
    ],
};

/// Emulated CPUs (qemu's names): no AVX at all; AVX2 and FMA without AVX-512.
const EMULATED_CPUS: [&str; 2] = ["Nehalem", "Haswell"];

/// glibc tunable that hides CPU features from glibc's run-time selection of function variants
/// (its FMA and AVX2 variants of `expf`, `sinf`, ... and its memory routines).
const GLIBC_MASK: &str = "glibc.cpu.hwcaps=-AVX,-AVX2,-FMA,-AVX512F";

fn crate_dir() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The command that runs `case` with `threads` worker threads and prints its JSON summary.
fn run_command(program: &str, prefix: &[&str], case: &Case, threads: usize) -> Command {
    let mut cmd = Command::new(program);
    cmd.current_dir(crate_dir())
        .args(prefix)
        .args(["run", case.scene, "--json", "--no-bag", "--duration"])
        .arg(case.duration_s.to_string())
        .args(["--threads", &threads.to_string()]);
    for o in case.overrides {
        cmd.args(["--set", o]);
    }
    cmd
}

/// Runs `cmd` and returns its JSON summary; panics with stderr if it fails.
fn summary(mut cmd: Command, what: &str) -> Value {
    let output = cmd
        .output()
        .unwrap_or_else(|e| panic!("{what}: cannot start: {e}"));
    assert!(
        output.status.success(),
        "{what}: {}\n{}",
        output.status,
        String::from_utf8_lossy(&output.stderr)
    );
    serde_json::from_slice(&output.stdout).unwrap_or_else(|e| {
        panic!(
            "{what}: not JSON ({e}): {}",
            String::from_utf8_lossy(&output.stdout)
        )
    })
}

fn native(case: &Case, threads: usize) -> Value {
    summary(
        run_command(env!("CARGO_BIN_EXE_sandstep"), &[], case, threads),
        &format!("{} on {threads} threads", case.name),
    )
}

fn digest(summary: &Value) -> &str {
    summary["state_digest"].as_str().expect("state_digest")
}

/// What a golden run pins: the steps, the state digest and every metric.
fn pin_of(summary: &Value) -> Value {
    json!({
        "steps": summary["steps"],
        "state_digest": summary["state_digest"],
        "metrics": summary["metrics"],
    })
}

/// The metrics whose values differ between `pinned` and `now`, one line each.
fn metric_changes(pinned: &Value, now: &Value) -> Vec<String> {
    let empty = Map::new();
    let (old, new) = (
        pinned["metrics"].as_object().unwrap_or(&empty),
        now["metrics"].as_object().unwrap_or(&empty),
    );
    let mut keys: Vec<&String> = old.keys().chain(new.keys()).collect();
    keys.sort();
    keys.dedup();
    keys.into_iter()
        .filter(|k| old.get(*k) != new.get(*k))
        .map(|k| format!("  {k}: pinned {:?}, now {:?}", old.get(k), new.get(k)))
        .collect()
}

#[test]
fn golden_runs_give_the_pinned_bits() {
    let path = crate_dir().join(PINS);
    let update = std::env::var_os("SANDSTEP_UPDATE_GOLDEN").is_some();
    let pins: Value = if update {
        json!({})
    } else {
        let text =
            std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
    };
    let mut now = Map::new();
    let mut changed = Vec::new();
    for case in &GOLDEN {
        let pin = pin_of(&native(case, 2));
        let pinned = &pins[case.name];
        if !update && *pinned != pin {
            changed.push(format!(
                "{} ({} for {} s, {:?}): steps {} -> {}, digest {} -> {}\n{}",
                case.name,
                case.scene,
                case.duration_s,
                case.overrides,
                pinned["steps"],
                pin["steps"],
                pinned["state_digest"],
                pin["state_digest"],
                metric_changes(pinned, &pin).join("\n")
            ));
        }
        now.insert(case.name.to_string(), pin);
    }
    if update {
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        let text = serde_json::to_string_pretty(&Value::Object(now)).unwrap() + "\n";
        std::fs::write(&path, text).unwrap();
        eprintln!("re-pinned {}", path.display());
        return;
    }
    assert!(
        changed.is_empty(),
        "the numbers changed (if on purpose, re-pin with SANDSTEP_UPDATE_GOLDEN=1 cargo test \
         --release --test determinism golden and say why in the commit):\n{}",
        changed.join("\n")
    );
}

#[test]
fn thread_count_and_glibc_variants_do_not_change_the_bits() {
    let reference = native(&PATHS, 2);
    // The check covers sleeping sand only if some falls asleep.
    let fell_asleep = reference["metrics"]["blocks_fell_asleep"].as_u64();
    assert!(fell_asleep > Some(0), "blocks_fell_asleep: {fell_asleep:?}");
    for threads in [1, 3] {
        assert_eq!(
            digest(&native(&PATHS, threads)),
            digest(&reference),
            "{threads} threads against 2"
        );
    }
    let mut masked = run_command(env!("CARGO_BIN_EXE_sandstep"), &[], &PATHS, 2);
    masked.env("GLIBC_TUNABLES", GLIBC_MASK);
    let masked = summary(masked, "with glibc's AVX/FMA variants masked");
    assert_eq!(digest(&masked), digest(&reference), "{GLIBC_MASK}");
    assert_eq!(masked["metrics"], reference["metrics"]);
}

/// The wide loops give the same bits with every instruction set (`SANDSTEP_SIMD`), and a name
/// the CPU or the program does not know is refused before any work, naming the variable.
#[test]
fn every_simd_instruction_set_gives_the_same_bits() {
    let reference = native(&PATHS, 2);
    let mut tried = Vec::new();
    for name in ["avx512", "avx2", "portable"] {
        let mut cmd = run_command(env!("CARGO_BIN_EXE_sandstep"), &[], &PATHS, 2);
        cmd.env("SANDSTEP_SIMD", name);
        let output = cmd.output().expect("run sandstep");
        if !output.status.success() {
            let stderr = String::from_utf8_lossy(&output.stderr);
            // Only a CPU without it may refuse an instruction set, and it must say so.
            assert!(
                name != "portable" && stderr.contains("SANDSTEP_SIMD") && stderr.contains(name),
                "SANDSTEP_SIMD={name}: {stderr}"
            );
            continue;
        }
        let run: Value = serde_json::from_slice(&output.stdout).expect("JSON summary");
        assert_eq!(digest(&run), digest(&reference), "SANDSTEP_SIMD={name}");
        tried.push(name);
    }
    eprintln!("instruction sets compared: {tried:?}");
    assert!(tried.contains(&"portable"));
    let mut bad = run_command(env!("CARGO_BIN_EXE_sandstep"), &[], &PATHS, 2);
    let output = bad
        .env("SANDSTEP_SIMD", "sse9")
        .output()
        .expect("run sandstep");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        !output.status.success() && stderr.contains("SANDSTEP_SIMD") && stderr.contains("sse9")
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
}

/// The qemu user-mode emulator, or a panic that says how to get it.
fn qemu() -> String {
    let program = "qemu-x86_64";
    match Command::new(program).arg("--version").output() {
        Ok(out) if out.status.success() => program.to_string(),
        _ => panic!(
            "{program} not found: this test runs the simulator on emulated CPUs. Install qemu \
             user mode (Debian/Ubuntu: apt-get install qemu-user; `.ci/run` does)"
        ),
    }
}

#[test]
#[cfg(target_arch = "x86_64")]
fn emulated_cpus_give_the_same_bits() {
    let qemu = qemu();
    let reference = native(&PATHS, 1);
    let runs: Vec<(&str, Value)> = std::thread::scope(|scope| {
        let handles: Vec<_> = EMULATED_CPUS
            .iter()
            .map(|cpu| {
                let qemu = &qemu;
                scope.spawn(move || {
                    let cmd = run_command(
                        qemu,
                        &["-cpu", cpu, env!("CARGO_BIN_EXE_sandstep")],
                        &PATHS,
                        1,
                    );
                    (*cpu, summary(cmd, &format!("under qemu -cpu {cpu}")))
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    for (cpu, run) in runs {
        assert_eq!(
            digest(&run),
            digest(&reference),
            "qemu -cpu {cpu} against this CPU:\n{}\n{}",
            run["metrics"],
            reference["metrics"]
        );
    }
}
