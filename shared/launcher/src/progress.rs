//! Progress display on work a user waits for (a launched session, a soak, the benchmarks): an
//! `indicatif` bar or spinner on stderr when stderr is a terminal. Otherwise nothing is drawn
//! and every line is printed plainly to stderr as before, so tests and CI that parse the
//! output see the same lines.

use sabr_node::errln;
use std::fmt::Display;
use std::io::IsTerminal;
use std::time::Duration;

use indicatif::{ProgressBar, ProgressStyle};

/// How often a spinner is redrawn without news.
const TICK: Duration = Duration::from_millis(200);

/// A progress display; cloning gives another handle on the same one.
#[derive(Debug, Clone)]
pub struct Progress {
    bar: Option<ProgressBar>,
}

impl Progress {
    /// A bar of `length` steps (e.g. seconds of a measuring window), drawn only on a terminal.
    pub fn bar(length: u64, unit: &str) -> Self {
        Self::drawn(|| {
            let style = ProgressStyle::with_template(&format!(
                "{{elapsed_precise}} [{{bar:40}}] {{pos}}/{{len}} {unit}, ETA {{eta}}  {{msg}}"
            ))
            .expect("the template is valid")
            .progress_chars("=> ");
            ProgressBar::new(length).with_style(style)
        })
    }

    /// A spinner with the elapsed time and a message, drawn only on a terminal.
    pub fn spinner() -> Self {
        Self::drawn(|| {
            let style = ProgressStyle::with_template("{spinner} {elapsed_precise}  {wide_msg}")
                .expect("the template is valid");
            ProgressBar::new_spinner().with_style(style)
        })
    }

    /// No display: every line is printed plainly.
    pub fn none() -> Self {
        Progress { bar: None }
    }

    fn drawn(make: impl FnOnce() -> ProgressBar) -> Self {
        if !std::io::stderr().is_terminal() {
            return Self::none();
        }
        let bar = make();
        bar.enable_steady_tick(TICK);
        Progress { bar: Some(bar) }
    }

    /// Prints `line` to stderr (above the bar while one is drawn).
    pub fn line(&self, line: impl Display) {
        match &self.bar {
            Some(bar) => bar.println(line.to_string()),
            None => errln!("{line}"),
        }
    }

    /// Sets the bar's position (steps done).
    pub fn set_position(&self, position: u64) {
        if let Some(bar) = &self.bar {
            bar.set_position(position);
        }
    }

    /// Sets the text shown beside the bar.
    pub fn set_message(&self, message: impl Display) {
        if let Some(bar) = &self.bar {
            bar.set_message(message.to_string());
        }
    }

    /// Removes the bar from the terminal.
    pub fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}
