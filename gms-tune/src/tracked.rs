//! The command line's hooks for long runs ([`gms_tune::run`]): a progress bar moved by the
//! device time waited, and Ctrl-C as the stop.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use gms_tune::run::Hooks;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// A progress bar per stage, in device milliseconds.
pub struct Bar {
    /// The current bar (hidden until a stage starts one).
    pub bar: ProgressBar,
}

impl Bar {
    /// No bar yet.
    pub fn new() -> Bar {
        Bar {
            bar: ProgressBar::hidden(),
        }
    }
}

impl Hooks for Bar {
    fn stage(&mut self, what: &str, seconds: f64) {
        self.bar.finish_and_clear();
        let bar = ProgressBar::with_draw_target(
            Some((seconds * 1000.0).max(1.0) as u64),
            ProgressDrawTarget::stderr(),
        );
        if let Ok(style) = ProgressStyle::with_template(
            "{prefix:>11} [{bar:32}] {percent:>3} %  {elapsed_precise} elapsed, about {eta} left",
        ) {
            bar.set_style(style.progress_chars("=> "));
        }
        bar.set_prefix(what.to_string());
        bar.enable_steady_tick(Duration::from_millis(200));
        self.bar = bar;
    }

    fn waited(&mut self, seconds: f64) {
        self.bar.inc((seconds * 1000.0) as u64);
    }
}

/// The stop flag set by Ctrl-C for the rest of the process.
pub fn ctrl_c() -> Arc<AtomicBool> {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    // A second handler cannot be set (a second run in one process): the run then ends only
    // on its own.
    let _ = ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst));
    stop
}
