//! No input panics: property tests over what a user hands the simulator. Scene YAML with its
//! bytes edited, `--set` overrides of every kind of value on every section, URDF text with
//! its bytes and numbers edited, and bag files cut and corrupted. Each input must give a
//! result or an error, never a panic; scenes that load are also built and stepped once.
//! Bounded: a fixed number of cases per property (proptest's `cases`), seeds from proptest's
//! own source, and the sand held to a small memory limit so a fine grid is refused quickly.

use std::path::Path;

use proptest::prelude::*;
use sandstep::bag::{BagReader, BagWriter};
use sandstep::robot::urdf_gen::hexapod_urdf_text;
use sandstep::robot::{write_hexapod_urdf, HexapodParams, RobotConfig, RobotSim};
use sandstep::scene::{Scene, Simulation};

/// The shipped scenes, as text.
const SCENES: [(&str, &str); 3] = [
    (
        "config/column_collapse.yaml",
        include_str!("../config/column_collapse.yaml"),
    ),
    (
        "config/robot_on_ground.yaml",
        include_str!("../config/robot_on_ground.yaml"),
    ),
    (
        "config/robot_on_sand.yaml",
        include_str!("../config/robot_on_sand.yaml"),
    ),
];

/// Memory the fuzzed scenes' sand may take (bytes): a grid finer than a few times the
/// shipped one is refused before it is allocated, as `--max-memory 0.3` does.
const FUZZ_MEMORY_LIMIT_BYTES: f64 = 3e8;

/// Cases per property in the suite: seconds of the suite's time.
const DEFAULT_CASES: u32 = 48;

/// Keys `--set` is tried on: every section, scalars, lists and maps.
const KEYS: &[&str] = &[
    "duration_s",
    "gravity_m_s2",
    "sand.dx_m",
    "sand.domain.min_m",
    "sand.domain.max_m",
    "sand.domain.walls.z_min",
    "sand.window",
    "sand.window.step_m",
    "sand.window.ahead_m",
    "sand.solver.cfl",
    "sand.solver.max_dt_s",
    "sand.solver.fixed_dt_s",
    "sand.solver.transfer",
    "sand.solver.sleep",
    "sand.solver.sleep.speed_m_s",
    "sand.solver.blowup_speed_m_s",
    "sand.materials",
    "sand.bodies",
    "column_collapse.aspect_ratio",
    "column_collapse.initial_length_m",
    "column_collapse.particles_per_cell",
    "robot.urdf",
    "robot.initial_pose.position_m",
    "robot.initial_pose.yaw_deg",
    "robot.gait.frequency_hz",
    "robot.physics.max_dt_s",
    "robot.motor.stiffness_nm_per_rad",
    "terrain.model",
    "terrain.rft.zeta_n_m3",
    "coupling.friction",
    "coupling.legs_yield_with",
    "coupling.load_prediction",
    "coupling.motor_impedance",
    "output.frame_interval_s",
    "node.state_rate_hz",
    "node.name",
];

/// Values `--set` is tried with: YAML of every type, and numbers at and past every edge.
const VALUES: &[&str] = &[
    "0",
    "-1",
    "1",
    "1e-30",
    "1e30",
    "1e308",
    "-1e308",
    ".nan",
    ".inf",
    "-.inf",
    "null",
    "~",
    "true",
    "''",
    "x",
    "[]",
    "[1]",
    "[1, 2, 3]",
    "[0, 0, 0]",
    "[-1e9, 0, 1e9]",
    "{}",
    "{a: 1}",
    "[.nan, 0, 0]",
    "0.001",
    "0.5",
    "3",
    "4294967296",
    "-0",
];

/// Wall time a fuzzed scene may step for before it is stopped (s): an override such as
/// `sand.solver.max_dt_s=1e-30` or `output.frame_interval_s=1e30` asks for a frame of
/// endless substeps, which is a slow input, not a panic. A hang guard, asserting nothing.
const STEP_FOR_AT_MOST_S: u64 = 2;

/// Loads `text` as a scene with `overrides`; if it loads, builds it and takes one frame (or
/// what of it [`STEP_FOR_AT_MOST_S`] allows, through the simulation's stop request).
fn load_build_and_step(file: &str, text: &str, overrides: &[String]) {
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::{mpsc, Arc};
    use std::time::Duration;

    let Ok(scene) = Scene::from_yaml(text, Path::new(file), overrides) else {
        return;
    };
    let stop = Arc::new(AtomicBool::new(false));
    let Ok(mut sim) = Simulation::new_unless(&scene, &stop) else {
        return;
    };
    let (stepped, done) = mpsc::channel::<()>();
    let guard = {
        let stop = stop.clone();
        std::thread::spawn(move || {
            if done
                .recv_timeout(Duration::from_secs(STEP_FOR_AT_MOST_S))
                .is_err()
            {
                stop.store(true, Ordering::Relaxed);
            }
        })
    };
    let first_frame_s = scene.config.output.frame_interval_s;
    let _ = sim.advance_to(first_frame_s);
    let _ = stepped.send(());
    guard.join().unwrap();
}

/// Cases per property: `PROPTEST_CASES` for a longer search, else [`DEFAULT_CASES`].
fn fuzz_cases() -> u32 {
    std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(DEFAULT_CASES)
}

fn setup() {
    sandstep::scene::memory::limit_to(FUZZ_MEMORY_LIMIT_BYTES);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: fuzz_cases(), ..ProptestConfig::default() })]

    /// Two `--set` overrides on a shipped scene.
    #[test]
    fn overrides_do_not_panic(
        scene in 0..SCENES.len(),
        sets in prop::collection::vec((0..KEYS.len(), 0..VALUES.len()), 1..3),
    ) {
        setup();
        let (file, text) = SCENES[scene];
        let overrides: Vec<String> =
            sets.iter().map(|&(k, v)| format!("{}={}", KEYS[k], VALUES[v])).collect();
        load_build_and_step(file, text, &overrides);
    }

    /// A shipped scene's text with a few bytes replaced, deleted or inserted.
    #[test]
    fn edited_scene_text_does_not_panic(
        scene in 0..SCENES.len(),
        edits in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>(), 0..3u8), 1..6),
    ) {
        setup();
        let (file, text) = SCENES[scene];
        let text = edit_bytes(text.as_bytes(), &edits);
        if let Ok(text) = String::from_utf8(text) {
            // Parsing and validation only: an edited number can ask for any grid.
            let _ = Scene::from_yaml(&text, Path::new(file), &[]);
        }
    }

    /// The hexapod's URDF with bytes edited or a number replaced by an edge value.
    #[test]
    fn edited_urdf_does_not_panic(
        edits in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>(), 0..3u8), 0..4),
        number in any::<prop::sample::Index>(),
        value in 0..VALUES.len(),
    ) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("hexapod.urdf");
        write_hexapod_urdf(&HexapodParams::default(), &path).unwrap();
        let text = hexapod_urdf_text(&HexapodParams::default(), "hexapod", "meshes/hexapod_leg.stl");
        let text = replace_a_number(&text, number, VALUES[value]);
        let bytes = edit_bytes(text.as_bytes(), &edits);
        std::fs::write(&path, bytes).unwrap();
        let cfg = RobotConfig { urdf: path, ..Default::default() };
        let _ = RobotSim::new(&cfg, [0.0, 0.0, -9.81]);
    }

    /// A bag cut short (a killed recording, a full disk), with a chunk's header damaged, or
    /// with bytes changed anywhere (inside a compressed chunk they aborted the `mcap` crate's
    /// message stream, which allocated a length decoded from them; `src/bag/chunks.rs`): read
    /// and reindexed.
    #[test]
    fn damaged_bags_do_not_panic(
        cut in any::<prop::sample::Index>(),
        header_edits in prop::collection::vec((0..CHUNK_HEADER_BYTES, any::<u8>()), 0..3),
        byte_edits in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..3),
    ) {
        let dir = tempfile::tempdir().unwrap();
        let bag = dir.path().join("damaged");
        let mut writer = BagWriter::create(&bag).unwrap();
        for i in 0..200u64 {
            let clock = sandstep::msgs::Clock {
                clock: sandstep::msgs::Time { sec: (i / 100) as i32, nanosec: (i % 100) as u32 * 10_000_000 },
            };
            writer.write("/clock", i * 10_000_000, &clock).unwrap();
        }
        let info = writer.finish().unwrap();
        let bytes = std::fs::read(&info.mcap_path).unwrap();
        let kept = cut.index(bytes.len() + 1);
        let mut damaged = bytes[..kept].to_vec();
        // The first chunk's record starts after the magic and the header record.
        let chunk = first_chunk_at(&bytes);
        for (offset, byte) in header_edits {
            if let Some(b) = damaged.get_mut(chunk + offset) {
                *b = byte;
            }
        }
        for (at, byte) in byte_edits {
            if !damaged.is_empty() {
                let i = at.index(damaged.len());
                damaged[i] = byte;
            }
        }
        std::fs::write(&info.mcap_path, damaged).unwrap();
        let _ = BagReader::open(&bag);
        std::fs::remove_file(bag.join("metadata.yaml")).unwrap();
        let _ = BagReader::open(&bag);
        if sandstep::bag::reindex(&bag).is_ok() {
            BagReader::open(&bag).expect("a reindexed bag reads");
        }
    }
}

/// Bytes of a chunk record before its compressed records: opcode, length, start and end
/// times, uncompressed size and CRC, the compression's name (`zstd`) and the records' length.
const CHUNK_HEADER_BYTES: usize = 1 + 8 + 8 + 8 + 8 + 4 + 4 + 4 + 8;

/// Where the first chunk record of an MCAP file starts: after the magic (8 bytes) and the
/// header record (opcode 0x01, length, body).
fn first_chunk_at(bytes: &[u8]) -> usize {
    let header_len = u64::from_le_bytes(bytes[9..17].try_into().unwrap()) as usize;
    8 + 9 + header_len
}

/// `bytes` with each edit applied: at a position, replace (0), delete (1) or insert (2) a byte.
fn edit_bytes(bytes: &[u8], edits: &[(prop::sample::Index, u8, u8)]) -> Vec<u8> {
    let mut out = bytes.to_vec();
    for (at, byte, kind) in edits {
        if out.is_empty() {
            out.push(*byte);
            continue;
        }
        let i = at.index(out.len());
        match kind {
            0 => out[i] = *byte,
            1 => {
                out.remove(i);
            }
            _ => out.insert(i, *byte),
        }
    }
    out
}

/// `text` with one of its numbers (attribute values such as `xyz="0 0 0.1"` hold several)
/// replaced by `value`.
fn replace_a_number(text: &str, which: prop::sample::Index, value: &str) -> String {
    let is_number_char = |c: char| c.is_ascii_digit() || c == '.' || c == '-' || c == 'e';
    let mut starts = Vec::new();
    let chars: Vec<(usize, char)> = text.char_indices().collect();
    for (k, &(i, c)) in chars.iter().enumerate() {
        let before = k.checked_sub(1).map(|p| chars[p].1);
        if c.is_ascii_digit() && !before.is_some_and(is_number_char) {
            starts.push(i);
        }
    }
    if starts.is_empty() {
        return text.to_string();
    }
    let start = starts[which.index(starts.len())];
    let end = text[start..]
        .find(|c: char| !is_number_char(c))
        .map_or(text.len(), |n| start + n);
    format!("{}{}{}", &text[..start], value, &text[end..])
}
