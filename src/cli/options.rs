//! The options several commands share, defined once: worker threads, `--set` overrides,
//! `--json`, `--duration`, the bag, and a study's runs spread over jobs.

use std::path::{Path, PathBuf};

/// `--max-memory GB`.
#[derive(clap::Args, Debug, Clone)]
pub struct MemoryLimit {
    /// Most memory the sand may take (GB); a scene needing more is refused before anything is
    /// allocated. Default: what the machine has available.
    #[arg(long, value_name = "GB")]
    pub max_memory: Option<f64>,
}

impl MemoryLimit {
    /// Holds every scene of this process to the limit, if one was given.
    pub fn apply(&self) -> anyhow::Result<()> {
        if let Some(gb) = self.max_memory {
            anyhow::ensure!(
                gb.is_finite() && gb > 0.0,
                "--max-memory {gb}: must be a finite number of GB > 0"
            );
            crate::scene::memory::limit_to(gb * crate::scene::memory::BYTES_PER_GB);
        }
        Ok(())
    }
}

/// `--list`, `--shard I/N`, `--run NAME`, `--merge`: a study's runs as independent jobs
/// (`docs/cluster.md`, [`crate::shard`]).
#[derive(clap::Args, Debug, Clone)]
pub struct Jobs {
    /// Print the names of the runs (a sweep's settings: study/setting), one per line, and
    /// exit; `--list | wc -l` sizes a job array.
    #[arg(long, conflicts_with_all = ["shard", "runs", "merge", "out"])]
    pub list: bool,
    /// Run shard I of N (I from 1, runs dealt round robin) into the shared --out folder, each
    /// run's result in a file of its own; --merge then writes the results.
    #[arg(long, value_name = "I/N", requires = "out", conflicts_with = "runs")]
    pub shard: Option<crate::shard::Shard>,
    /// Run only the run of this name (repeatable; names from --list) into --out, as a shard.
    #[arg(long = "run", value_name = "NAME", requires = "out")]
    pub runs: Vec<String>,
    /// Merge the runs' results that shards left in --out into the study's results (as one
    /// process writes them), then print them.
    #[arg(long, requires = "out", conflicts_with_all = ["shard", "runs"])]
    pub merge: bool,
}

impl Jobs {
    /// The runs this process runs.
    pub fn selection(&self) -> crate::shard::Selection {
        use crate::shard::Selection;
        match (&self.shard, self.runs.is_empty()) {
            (Some(shard), _) => Selection::Shard(*shard),
            (None, false) => Selection::Named(self.runs.clone()),
            (None, true) => Selection::All,
        }
    }
}

/// Parent of the default bag directories.
const DEFAULT_BAG_PARENT: &str = "bags";

/// `--threads N`.
#[derive(clap::Args, Debug, Clone)]
pub struct Threads {
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
}

impl Threads {
    /// Sizes rayon's global pool (once per process).
    pub fn apply(&self) -> anyhow::Result<()> {
        if let Some(n) = self.threads {
            anyhow::ensure!(n > 0, "--threads must be at least 1");
            rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build_global()?;
        }
        Ok(())
    }
}

/// `--set KEY.PATH=VALUE`, repeatable.
#[derive(clap::Args, Debug, Clone)]
pub struct Overrides {
    /// Change one value of the file, e.g. --set sand.dx_m=0.01 or --set cycles=2; the value is
    /// YAML (repeatable).
    #[arg(long = "set", value_name = "KEY.PATH=VALUE")]
    pub overrides: Vec<String>,
}

/// `--json`.
#[derive(clap::Args, Debug, Clone, Copy)]
pub struct Json {
    /// Print one JSON object on stdout instead of the human summary.
    #[arg(long)]
    pub json: bool,
}

impl Json {
    /// Progress bars are drawn unless the output is JSON.
    pub fn show_progress(self) -> bool {
        !self.json
    }
}

/// `--duration S`, checked to be a finite, positive number of seconds.
pub fn check_duration(duration_s: Option<f64>) -> anyhow::Result<Option<f64>> {
    if let Some(d) = duration_s {
        anyhow::ensure!(
            d.is_finite(),
            "--duration {d} must be a finite number of seconds"
        );
        anyhow::ensure!(d > 0.0, "--duration {d} must be > 0 seconds");
    }
    Ok(duration_s)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each bad duration is told what is wrong with it (issue 22: `inf` was told "> 0").
    #[test]
    fn bad_durations_say_what_is_wrong() {
        let message = |d: f64| check_duration(Some(d)).unwrap_err().to_string();
        assert!(
            message(f64::INFINITY).contains("finite"),
            "{}",
            message(f64::INFINITY)
        );
        assert!(
            message(f64::NAN).contains("finite"),
            "{}",
            message(f64::NAN)
        );
        assert!(message(0.0).contains("> 0"), "{}", message(0.0));
        assert!(message(-1.0).contains("> 0"), "{}", message(-1.0));
        assert_eq!(check_duration(Some(0.5)).unwrap(), Some(0.5));
    }
}

/// Where a run records its bag.
#[derive(clap::Args, Debug, Clone)]
pub struct BagArgs {
    /// Bag directory to create (default bags/<scene>-<YYYYmmdd-HHMMSS>).
    #[arg(long = "bag", value_name = "DIR", conflicts_with = "no_bag")]
    pub dir: Option<PathBuf>,
    /// Do not record a bag.
    #[arg(long)]
    pub no_bag: bool,
}

impl BagArgs {
    /// The bag directory for `scene_name`, or `None` with `--no-bag`.
    pub fn dir(&self, scene_name: &str) -> Option<PathBuf> {
        if self.no_bag {
            return None;
        }
        Some(self.dir.clone().unwrap_or_else(|| {
            crate::ros::default_bag_dir(Path::new(DEFAULT_BAG_PARENT), scene_name)
        }))
    }
}
