//! `sandstep run` with its bag: runs a scene headless and records what the node would publish.
//! The command line and `sandstep experiment` both run scenes through [`record_run`].

use std::path::{Path, PathBuf};

use super::publishing::{PublishError, Publishing};
use crate::bag::{BagInfo, BagWriter};
use crate::scene::RunError;
use crate::scene::{
    build_simulation, run_scene_observed, run_simulation_observed, Observer, RunOptions,
    RunSummary, Scene,
};

/// A finished run and its bag.
#[derive(Clone, Debug)]
pub struct RecordedRun {
    pub summary: RunSummary,
    /// The finished bag; `None` when not recording.
    pub bag: Option<BagInfo>,
}

/// Why a recorded run failed. The bag, if any, is finished (readable) in every case but
/// [`RecordError::Start`]. The message includes the cause, so it is not also given as the
/// error's source (which `{:#}` would print a second time).
#[derive(thiserror::Error, Debug)]
pub enum RecordError {
    #[error("running {}: {cause}", scene.display())]
    Run {
        scene: PathBuf,
        cause: Box<RunError>,
    },
    #[error("running {} (the bag so far is in {}): {cause}", scene.display(), bag.display())]
    RunRecorded {
        scene: PathBuf,
        bag: PathBuf,
        cause: Box<RunError>,
    },
    #[error("recording {}: {cause}", bag.display())]
    Start {
        bag: PathBuf,
        cause: Box<PublishError>,
    },
    #[error("finishing the bag {}: {cause}", bag.display())]
    Finish {
        bag: PathBuf,
        cause: Box<PublishError>,
    },
}

impl RecordError {
    /// The simulation's error, if the run itself failed (not the recording).
    pub fn run_error(&self) -> Option<&RunError> {
        match self {
            RecordError::Run { cause, .. } | RecordError::RunRecorded { cause, .. } => {
                Some(cause.as_ref())
            }
            _ => None,
        }
    }
}

/// Calls two observers in turn.
struct Both<'a>(&'a mut dyn Observer, &'a mut dyn Observer);

impl Observer for Both<'_> {
    fn observe(
        &mut self,
        sim: &mut crate::scene::Simulation,
    ) -> Result<(), crate::scene::ObserverError> {
        self.0.observe(sim)?;
        self.1.observe(sim)
    }
}

/// Runs `scene` like [`run_scene_observed`] (calling `observer` at time 0 and after every
/// frame), recording into a new bag at `bag_dir` if given. The bag is finished on a
/// simulation error too, so what was recorded stays readable.
pub fn record_run(
    scene: &Scene,
    opts: &RunOptions,
    bag_dir: Option<&Path>,
    observer: &mut dyn Observer,
) -> Result<RecordedRun, RecordError> {
    let scene_file = || scene.file.clone();
    let Some(dir) = bag_dir else {
        let summary =
            run_scene_observed(scene, opts, observer).map_err(|source| RecordError::Run {
                scene: scene_file(),
                cause: Box::new(source),
            })?;
        return Ok(RecordedRun { summary, bag: None });
    };
    let start = |source: PublishError| RecordError::Start {
        bag: dir.to_path_buf(),
        cause: Box::new(source),
    };
    // Built before the bag is created: a scene that fails to build, or a stop while it
    // builds, leaves no bag behind.
    let sim = build_simulation(scene, opts).map_err(|source| RecordError::Run {
        scene: scene_file(),
        cause: Box::new(source),
    })?;
    let writer = BagWriter::create(dir).map_err(|e| start(e.into()))?;
    let mut recorder = Publishing::new(scene, &sim, None, Some(writer)).map_err(start)?;
    let outcome = run_simulation_observed(scene, sim, opts, &mut Both(&mut recorder, observer));
    let finished = recorder.finish();
    let summary = outcome.map_err(|source| RecordError::RunRecorded {
        scene: scene_file(),
        bag: dir.to_path_buf(),
        cause: Box::new(source),
    })?;
    let bag = finished.map_err(|source| RecordError::Finish {
        bag: dir.to_path_buf(),
        cause: Box::new(source),
    })?;
    Ok(RecordedRun { summary, bag })
}
