//! The command line's progress bars on stderr, drawn from a job's reports
//! ([`crate::progress::ProgressDisplay`]): one bar over a single run's simulated time (with its
//! ETA and status), or over a series of runs (an experiment's, a sweep's) one bar over all runs'
//! simulated time, so that the ETA weighs each run by its length, and one within the current
//! run, with a line per finished run above them.

use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};

use crate::progress::{Progress, ProgressDisplay};

/// A single run: elapsed wall time, the bar, simulated ms, ETA and status.
const RUN_TEMPLATE: &str = "{elapsed_precise} [{bar:40}] {pos}/{len} ms sim, eta {eta} ({msg})";
/// A run without an end (a node until stopped).
const OPEN_RUN_TEMPLATE: &str = "{elapsed_precise} {pos} ms sim ({msg})";
/// A series: the bar over all runs, and the current run's below it.
const SERIES_TEMPLATE: &str = "{elapsed_precise} [{bar:30}] {msg}, eta {eta}";
const SERIES_RUN_TEMPLATE: &str = "  {msg:24} [{bar:30}] {pos}/{len} ms sim";
/// How often the series bar redraws by itself (its elapsed time and ETA).
const TICK: Duration = Duration::from_secs(1);

/// Progress bars on stderr (or hidden, for `--json` runs).
pub struct Bars {
    multi: MultiProgress,
    state: Mutex<State>,
}

#[derive(Default)]
struct State {
    /// The bar over all runs of a series (none for a single run).
    series: Option<ProgressBar>,
    /// The current run's bar.
    run: Option<ProgressBar>,
    run_count: usize,
    runs_done: usize,
    /// Simulated time of the runs finished (s).
    done_sim_s: f64,
}

/// Simulated seconds as a bar position (ms).
fn bar_ms(time_s: f64) -> u64 {
    (time_s * 1e3) as u64
}

fn style(template: &str) -> ProgressStyle {
    ProgressStyle::with_template(template)
        .expect("valid template")
        .progress_chars("=> ")
}

impl Bars {
    /// Bars drawn on stderr if `visible`, else nowhere.
    pub fn new(visible: bool) -> Self {
        Bars {
            multi: MultiProgress::with_draw_target(if visible {
                ProgressDrawTarget::stderr()
            } else {
                ProgressDrawTarget::hidden()
            }),
            state: Mutex::new(State::default()),
        }
    }

    /// A [`Progress`] handle reporting to bars on stderr (hidden unless `visible`).
    pub fn progress(visible: bool) -> Progress {
        Progress::to(Arc::new(Bars::new(visible)))
    }

    fn state(&self) -> MutexGuard<'_, State> {
        // A panic while drawing leaves plain counters behind: still usable.
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Prints `line` on stderr, above the bars when they are drawn.
    fn println(&self, line: &str) {
        if !line.is_empty() {
            self.multi.suspend(|| eprintln!("{line}"));
        }
    }
}

impl ProgressDisplay for Bars {
    fn plan(&self, durations_s: &[f64]) {
        let mut state = self.state();
        let series = self
            .multi
            .add(ProgressBar::new(bar_ms(durations_s.iter().sum())));
        series.set_style(style(SERIES_TEMPLATE));
        series.enable_steady_tick(TICK);
        state.series = Some(series);
        state.run_count = durations_s.len();
    }

    fn start_run(&self, name: &str, duration_s: Option<f64>) {
        let mut state = self.state();
        let run = state
            .run
            .get_or_insert_with(|| self.multi.add(ProgressBar::new(1)))
            .clone();
        run.set_position(0);
        match (&state.series, duration_s) {
            (Some(series), _) => {
                run.set_style(style(SERIES_RUN_TEMPLATE));
                run.set_length(bar_ms(duration_s.unwrap_or(0.0)));
                run.set_message(name.to_string());
                series.set_message(format!(
                    "run {} of {}",
                    state.runs_done + 1,
                    state.run_count
                ));
            }
            (None, Some(d)) => {
                run.set_style(style(RUN_TEMPLATE));
                run.set_length(bar_ms(d));
            }
            (None, None) => {
                run.set_style(style(OPEN_RUN_TEMPLATE));
                run.unset_length();
            }
        }
    }

    fn advance(&self, time_s: f64, status: &str) {
        let state = self.state();
        if let Some(run) = &state.run {
            run.set_position(bar_ms(time_s));
            if state.series.is_none() {
                run.set_message(status.to_string());
            }
        }
        if let Some(series) = &state.series {
            series.set_position(bar_ms(state.done_sim_s + time_s));
        }
    }

    fn finish_run(&self, duration_s: f64, line: &str) {
        let mut state = self.state();
        state.done_sim_s += duration_s;
        state.runs_done += 1;
        if let Some(series) = &state.series {
            series.set_position(bar_ms(state.done_sim_s));
        }
        drop(state);
        self.println(line);
    }

    fn skip_run(&self, duration_s: f64, line: &str) {
        let mut state = self.state();
        if let Some(series) = &state.series {
            let length = series.length().unwrap_or(0);
            series.set_length(length.saturating_sub(bar_ms(duration_s)));
        }
        state.runs_done += 1;
        drop(state);
        self.println(line);
    }

    fn done(&self) {
        let state = self.state();
        for bar in state.run.iter().chain(&state.series) {
            bar.finish_and_clear();
        }
    }

    fn abandon(&self) {
        let state = self.state();
        for bar in state.run.iter().chain(&state.series) {
            bar.abandon();
        }
    }
}
