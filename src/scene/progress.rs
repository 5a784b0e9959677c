//! Progress across a series of runs (`sandstep experiment`, `sandstep sweep`): one bar over
//! the simulated time of all runs, so that the ETA weighs each run by its length, and one
//! within the current run; a line per finished run above them.

use std::cell::Cell;
use std::time::Duration;

use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};

/// The bars of a series of runs. Positions are in milliseconds of simulated time.
pub struct RunsProgress {
    multi: MultiProgress,
    /// All runs' simulated time (ms).
    runs: ProgressBar,
    /// The current run's simulated time (ms).
    run: ProgressBar,
    run_count: usize,
    /// Simulated time of the runs finished (s), and their number.
    done_sim_s: Cell<f64>,
    done_runs: Cell<usize>,
}

/// Simulated seconds as a bar position (ms).
fn bar_ms(time_s: f64) -> u64 {
    (time_s * 1e3) as u64
}

impl RunsProgress {
    /// Bars for runs lasting `durations_s` (simulated s each), drawn on stderr if `visible`.
    pub fn new(visible: bool, durations_s: &[f64]) -> Self {
        let multi = MultiProgress::with_draw_target(if visible {
            ProgressDrawTarget::stderr()
        } else {
            ProgressDrawTarget::hidden()
        });
        let overall = multi.add(ProgressBar::new(bar_ms(durations_s.iter().sum())));
        overall.set_style(
            ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {msg}, eta {eta}")
                .expect("valid template")
                .progress_chars("=> "),
        );
        let run = multi.add(ProgressBar::new(1));
        run.set_style(
            ProgressStyle::with_template("  {msg:24} [{bar:30}] {pos}/{len} ms sim")
                .expect("valid template")
                .progress_chars("=> "),
        );
        overall.enable_steady_tick(Duration::from_secs(1));
        RunsProgress {
            multi,
            runs: overall,
            run,
            run_count: durations_s.len(),
            done_sim_s: Cell::new(0.0),
            done_runs: Cell::new(0),
        }
    }

    /// The run `name`, lasting `duration_s`, starts.
    pub fn start(&self, name: &str, duration_s: f64) {
        self.run.set_length(bar_ms(duration_s));
        self.run.set_position(0);
        self.run.set_message(name.to_string());
        self.runs.set_message(format!(
            "run {} of {}",
            self.done_runs.get() + 1,
            self.run_count
        ));
    }

    /// The current run has reached `time_s` of simulated time.
    pub fn advance(&self, time_s: f64) {
        self.run.set_position(bar_ms(time_s));
        self.runs
            .set_position(bar_ms(self.done_sim_s.get() + time_s));
    }

    /// A run not simulated now (kept from an earlier attempt): it leaves the total, so that the
    /// ETA counts only what is simulated now; `line` is printed.
    pub fn skip(&self, duration_s: f64, line: &str) {
        let length = self.runs.length().unwrap_or(0);
        self.runs
            .set_length(length.saturating_sub(bar_ms(duration_s)));
        self.done_runs.set(self.done_runs.get() + 1);
        self.println(line);
    }

    /// The current run, lasting `duration_s`, is over; `line` says how it went.
    pub fn finish(&self, duration_s: f64, line: &str) {
        self.done_sim_s.set(self.done_sim_s.get() + duration_s);
        self.done_runs.set(self.done_runs.get() + 1);
        self.runs.set_position(bar_ms(self.done_sim_s.get()));
        self.println(line);
    }

    /// Prints `line` on stderr, above the bars when they are drawn.
    fn println(&self, line: &str) {
        self.multi.suspend(|| eprintln!("{line}"));
    }

    /// Removes the bars.
    pub fn clear(&self) {
        self.run.finish_and_clear();
        self.runs.finish_and_clear();
    }
}
