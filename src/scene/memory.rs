//! The memory a scene's sand will need, estimated before anything is allocated and checked
//! against what the machine has free (`MemAvailable` in `/proc/meminfo`) or the limit given
//! with `--max-memory`. A mistyped `sand.dx_m` or domain is refused naming both, instead of
//! aborting the process inside an allocation.

use std::sync::OnceLock;

use super::build::body_particle_bound;
use super::{RunError, Scene};
use crate::mpm::memory::estimated_bytes;
use crate::terrain::TerrainModel;

/// Where the kernel tells the memory free for new allocations without swapping.
const MEMINFO: &str = "/proc/meminfo";
/// Its line: `MemAvailable:   12345678 kB`.
const MEM_AVAILABLE_KEY: &str = "MemAvailable:";
const BYTES_PER_KIB: f64 = 1024.0;
/// Bytes per gigabyte, as `--max-memory` and the messages count them.
pub const BYTES_PER_GB: f64 = 1e9;

/// The limit set by `--max-memory` (bytes), for the whole process.
static LIMIT_BYTES: OnceLock<f64> = OnceLock::new();

/// Sets the memory a scene's sand may take (bytes), instead of what the machine has free. The
/// first call wins.
pub fn limit_to(bytes: f64) {
    let _ = LIMIT_BYTES.set(bytes);
}

/// The limit the sand is held to, and what it is: `--max-memory`, or the machine's free
/// memory; `None` when neither is known.
fn limit() -> Option<(f64, &'static str)> {
    if let Some(&bytes) = LIMIT_BYTES.get() {
        return Some((bytes, "the --max-memory limit"));
    }
    available_bytes().map(|bytes| (bytes, "this machine's available memory"))
}

/// `MemAvailable` (bytes), if the kernel tells it.
fn available_bytes() -> Option<f64> {
    let text = std::fs::read_to_string(MEMINFO).ok()?;
    let line = text.lines().find(|l| l.starts_with(MEM_AVAILABLE_KEY))?;
    let kib: f64 = line[MEM_AVAILABLE_KEY.len()..]
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()?;
    Some(kib * BYTES_PER_KIB)
}

/// The particles and bytes the scene's MPM sand would take; `None` without MPM sand.
pub fn estimate(scene: &Scene) -> Option<(f64, f64)> {
    let sand = scene.sand()?;
    let config = &scene.config;
    if config.robot.is_some() && config.terrain.model == TerrainModel::Rft {
        return None;
    }
    let particles: f64 = scene
        .bodies()
        .iter()
        .map(|body| body_particle_bound(body, sand.dx_m))
        .sum();
    let extent = [0, 1, 2].map(|a| (sand.domain.max_m[a] - sand.domain.min_m[a]) as f64);
    let bytes = estimated_bytes(
        sand.dx_m as f64,
        extent,
        particles,
        sand.solver.sleep.is_some(),
    );
    Some((particles, bytes))
}

/// Refuses a scene whose sand would need more memory than the limit ([`limit_to`], else what
/// the machine has free), naming `sand.dx_m` and the domain.
pub fn check(scene: &Scene) -> Result<(), RunError> {
    let (Some((particles, bytes)), Some((limit, what))) = (estimate(scene), limit()) else {
        return Ok(());
    };
    if bytes <= limit {
        return Ok(());
    }
    let sand = scene.sand().expect("estimated");
    Err(RunError::Memory(format!(
        "sand.dx_m = {} m over the domain sand.domain {:?}..{:?} m would take {:.3e} particles \
         and about {} GB, more than {what} ({} GB): coarsen sand.dx_m, shrink sand.domain or \
         the sand bodies, or set --max-memory (GB)",
        sand.dx_m,
        sand.domain.min_m,
        sand.domain.max_m,
        particles,
        gigabytes(bytes),
        gigabytes(limit),
    )))
}

/// `bytes` in GB, to four figures (in powers of ten when huge).
fn gigabytes(bytes: f64) -> String {
    const PLAIN_BELOW_GB: f64 = 1e4;
    let gb = bytes / BYTES_PER_GB;
    if gb < PLAIN_BELOW_GB {
        format!("{gb:.3}")
    } else {
        format!("{gb:.3e}")
    }
}
