//! A run reports its progress through the `Progress` handle of its options (what the command
//! line draws as bars): the run's name and length first, then each frame's simulated time in
//! order up to the end, then that it is done; a run with no display reports nowhere.

use std::path::Path;
use std::sync::{Arc, Mutex};

use sandstep::progress::{Progress, ProgressDisplay};
use sandstep::scene::{run_scene, RunOptions, Scene};

/// Every report, in order.
#[derive(Default)]
struct Recorder(Mutex<Vec<Report>>);

#[derive(Clone, Debug, PartialEq)]
enum Report {
    Plan(usize),
    Start(String, Option<f64>),
    Advance(f64, String),
    Finish(f64),
    Skip(f64),
    Done,
    Abandon,
}

impl Recorder {
    fn push(&self, r: Report) {
        self.0.lock().unwrap().push(r);
    }
}

impl ProgressDisplay for Recorder {
    fn plan(&self, durations_s: &[f64]) {
        self.push(Report::Plan(durations_s.len()));
    }
    fn start_run(&self, name: &str, duration_s: Option<f64>) {
        self.push(Report::Start(name.into(), duration_s));
    }
    fn advance(&self, time_s: f64, status: &str) {
        self.push(Report::Advance(time_s, status.into()));
    }
    fn finish_run(&self, duration_s: f64, _line: &str) {
        self.push(Report::Finish(duration_s));
    }
    fn skip_run(&self, duration_s: f64, _line: &str) {
        self.push(Report::Skip(duration_s));
    }
    fn done(&self) {
        self.push(Report::Done);
    }
    fn abandon(&self) {
        self.push(Report::Abandon);
    }
}

#[test]
fn a_run_reports_its_frames_in_order_then_done() {
    let scene = Scene::load(Path::new("config/robot_on_ground.yaml"), &[]).unwrap();
    let recorder = Arc::new(Recorder::default());
    let opts = RunOptions {
        duration_s: Some(0.2),
        progress: Progress::to(recorder.clone()),
        ..RunOptions::default()
    };
    let summary = run_scene(&scene, &opts).unwrap();
    let reports = recorder.0.lock().unwrap().clone();
    assert_eq!(
        reports.first(),
        Some(&Report::Start(scene.config.name.clone(), Some(0.2)))
    );
    assert_eq!(reports.last(), Some(&Report::Done));
    let times: Vec<f64> = reports
        .iter()
        .filter_map(|r| match r {
            Report::Advance(t, status) => {
                assert!(status.starts_with("step "), "{status}");
                Some(*t)
            }
            _ => None,
        })
        .collect();
    let frames = (0.2 / scene.config.output.frame_interval_s).ceil() as usize;
    assert_eq!(times.len(), frames, "one report per frame: {times:?}");
    assert!(times.windows(2).all(|w| w[0] < w[1]), "{times:?}");
    assert!((times.last().unwrap() - 0.2).abs() < 1e-12);
    assert!((summary.sim_time_s - 0.2).abs() < 1e-6);
    assert_eq!(reports.len(), frames + 2, "nothing else: {reports:?}");
}
