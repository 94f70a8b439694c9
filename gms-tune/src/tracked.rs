//! The link as a bench for long runs: a progress bar moved by the device time waited, and
//! Ctrl-C turned into a clean stop (the requests that end a run safely still go out).

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use gms_ident::Error;
use gms_ident::bench::Bench;
use gms_tune::Link;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// The link as a bench whose waits move a progress bar (in device milliseconds) and whose
/// requests stop once the user pressed Ctrl-C.
pub struct Tracked<'a> {
    /// The link.
    pub link: &'a mut Link,
    /// The current progress bar (hidden until a run starts one).
    pub bar: ProgressBar,
    stop: Arc<AtomicBool>,
}

impl<'a> Tracked<'a> {
    /// The link, with Ctrl-C caught for the rest of the process.
    pub fn new(link: &'a mut Link) -> Tracked<'a> {
        let stop = Arc::new(AtomicBool::new(false));
        let flag = stop.clone();
        // A second handler cannot be set (a second run in one process): the run then ends
        // only on its own.
        let _ = ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst));
        Tracked {
            link,
            bar: ProgressBar::hidden(),
            stop,
        }
    }

    fn interrupted(&self) -> Result<(), Error> {
        if self.stop.load(Ordering::SeqCst) {
            Err(Error::Device("interrupted (Ctrl-C)".into()))
        } else {
            Ok(())
        }
    }

    /// A new bar for `what`, `seconds` of device time long.
    pub fn start(&mut self, what: &str, seconds: f64) {
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
}

impl Bench for Tracked<'_> {
    fn request(&mut self, line: &str) -> Result<(Vec<String>, String), Error> {
        // What an interrupted run sends to end safely goes out even after Ctrl-C.
        let safe = line == "disable"
            || line == "status"
            || line.starts_with("set lim.pos_")
            || line.starts_with("set ff.gain ");
        if !safe {
            self.interrupted()?;
        }
        Bench::request(&mut *self.link, line)
    }

    fn wait(&mut self, seconds: f64) -> Result<(), Error> {
        self.interrupted()?;
        Bench::wait(&mut *self.link, seconds)?;
        if seconds.is_finite() && seconds > 0.0 {
            self.bar.inc((seconds * 1000.0) as u64);
        }
        self.interrupted()
    }
}
