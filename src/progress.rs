//! How a long job (a run, a node, an experiment's or a sweep's series of runs) tells how far it
//! has got. The library only reports, through a [`Progress`] handle in its options; the command
//! line draws the reports as bars (`crate::cli::progress`). The default handle reports nowhere.

use std::fmt;
use std::sync::Arc;

/// Something that shows a job's progress: the command line's bars, or a test's recorder.
pub trait ProgressDisplay: Send + Sync {
    /// A series of runs of these simulated durations (s) is about to start.
    fn plan(&self, durations_s: &[f64]);
    /// The run `name` starts; it lasts `duration_s` of simulated time, or until stopped.
    fn start_run(&self, name: &str, duration_s: Option<f64>);
    /// The current run has reached `time_s` of simulated time; `status` says how it goes.
    fn advance(&self, time_s: f64, status: &str);
    /// The current run, of `duration_s` simulated seconds, is over; `line` says how it went.
    fn finish_run(&self, duration_s: f64, line: &str);
    /// A run of `duration_s` that is not simulated now (kept from an earlier attempt).
    fn skip_run(&self, duration_s: f64, line: &str);
    /// The job is over: nothing more to show.
    fn done(&self);
    /// The job stopped on an error: leave what was shown as it is.
    fn abandon(&self);
}

/// Where a job reports its progress: to a [`ProgressDisplay`], or nowhere (the default).
#[derive(Clone, Default)]
pub struct Progress(Option<Arc<dyn ProgressDisplay>>);

impl Progress {
    /// Reports nowhere.
    pub fn none() -> Self {
        Progress(None)
    }

    /// Reports to `display`.
    pub fn to(display: Arc<dyn ProgressDisplay>) -> Self {
        Progress(Some(display))
    }

    /// Calls `report` on the display, if any.
    fn report(&self, report: impl FnOnce(&dyn ProgressDisplay)) {
        if let Some(display) = &self.0 {
            report(display.as_ref());
        }
    }

    pub fn plan(&self, durations_s: &[f64]) {
        self.report(|d| d.plan(durations_s));
    }

    pub fn start_run(&self, name: &str, duration_s: Option<f64>) {
        self.report(|d| d.start_run(name, duration_s));
    }

    /// Reports `time_s`; `status` is only built when someone shows it.
    pub fn advance(&self, time_s: f64, status: impl FnOnce() -> String) {
        self.report(|d| d.advance(time_s, &status()));
    }

    pub fn finish_run(&self, duration_s: f64, line: &str) {
        self.report(|d| d.finish_run(duration_s, line));
    }

    pub fn skip_run(&self, duration_s: f64, line: &str) {
        self.report(|d| d.skip_run(duration_s, line));
    }

    pub fn done(&self) {
        self.report(|d| d.done());
    }

    pub fn abandon(&self) {
        self.report(|d| d.abandon());
    }

    /// Passes `result` through, abandoning the display first if it is an error.
    pub fn abandon_on_error<T, E>(&self, result: Result<T, E>) -> Result<T, E> {
        if result.is_err() {
            self.abandon();
        }
        result
    }
}

impl fmt::Debug for Progress {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(if self.0.is_some() {
            "Progress(shown)"
        } else {
            "Progress(none)"
        })
    }
}
