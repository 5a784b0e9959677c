//! `sandstep bench-rft`: how much faster than real time the robot walks on resistive force
//! theory ground, its bag recorded, as `sandstep run` runs it: the scene built, simulated and
//! its bag written and finished, all inside the timed wall time.

use std::path::Path;
use std::time::Instant;

use serde::Serialize;

use crate::ros::{record_run, RecordError};
use crate::scene::{NoObserver, RunOptions, Scene};

/// One timed run.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct RftBenchRun {
    /// Whether its bag was recorded.
    pub bag: bool,
    /// Simulated time (s).
    pub sim_time_s: f64,
    /// Wall time of the whole run: build, simulation, bag (s).
    pub wall_time_s: f64,
    /// Rapier steps.
    pub steps: u64,
    /// Size of the bag's files (bytes; 0 without a bag).
    pub bag_bytes: u64,
}

impl RftBenchRun {
    /// Simulated seconds per wall-clock second.
    pub fn real_time_factor(&self) -> f64 {
        self.sim_time_s / self.wall_time_s
    }
}

/// Runs `scene` (which must be on RFT ground) for `duration_s` of simulated time, its bag
/// recorded into `bag_dir` when given (the caller removes it), and times it.
pub fn time_run(
    scene: &Scene,
    duration_s: f64,
    bag_dir: Option<&Path>,
) -> Result<RftBenchRun, RecordError> {
    let opts = RunOptions {
        duration_s: Some(duration_s),
        out_dir: None,
        progress: Default::default(),
        stop: None,
    };
    let wall = Instant::now();
    let run = record_run(scene, &opts, bag_dir, &mut NoObserver)?;
    let wall_time_s = wall.elapsed().as_secs_f64();
    let bag_bytes = run.bag.as_ref().map_or(0, |bag| directory_bytes(&bag.dir));
    Ok(RftBenchRun {
        bag: bag_dir.is_some(),
        sim_time_s: run.summary.sim_time_s,
        wall_time_s,
        steps: run.summary.steps,
        bag_bytes,
    })
}

/// Total size of the files directly in `dir` (bytes); 0 if it cannot be read.
fn directory_bytes(dir: &Path) -> u64 {
    std::fs::read_dir(dir)
        .map(|entries| {
            entries
                .filter_map(|e| e.ok()?.metadata().ok())
                .map(|m| m.len())
                .sum()
        })
        .unwrap_or(0)
}

/// The best and the median of `values` (None when empty).
pub fn best_and_median(values: &[f64]) -> Option<(f64, f64)> {
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    let n = sorted.len();
    let median = match n {
        0 => return None,
        _ if n % 2 == 1 => sorted[n / 2],
        _ => 0.5 * (sorted[n / 2 - 1] + sorted[n / 2]),
    };
    Some((sorted[n - 1], median))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn best_is_the_largest_and_the_median_the_middle() {
        assert_eq!(best_and_median(&[3.0, 1.0, 2.0]), Some((3.0, 2.0)));
        assert_eq!(best_and_median(&[4.0, 1.0, 2.0, 3.0]), Some((4.0, 2.5)));
        assert_eq!(best_and_median(&[]), None);
    }
}
