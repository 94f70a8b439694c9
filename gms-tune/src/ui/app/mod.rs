//! The window's state and drawing: what the worker reports, shown; what the user does, sent.
//! Nothing here talks to the device: the worker does ([`super::worker`]).

use std::collections::VecDeque;
use std::path::PathBuf;
use std::time::Duration;

use egui::{Color32, RichText};
use egui_plot::{Legend, Line, Plot, PlotPoints, Points};
use gms_core::device::StatusReply;
use gms_core::friction::model::FrictionModel;
use gms_core::protocol::{Command, ParamId};

mod experiments;
mod frf;
mod friction;
mod learn;
mod live;
mod map;
mod motion;
mod params;

use super::worker::{Cmd, Endpoint, Event, Job, Outcome, TelemetrySample, Worker};
use crate::params::Listed;

/// Samples kept: 60 s of the 1 kHz stream.
const KEEP: usize = 60_000;

/// One parameter of the tree.
#[derive(Debug, Clone)]
pub struct Row {
    /// What `list` said (the value is the device's, updated after each set).
    pub listed: Listed,
    /// The text in the field.
    pub edit: String,
    /// The device's refusal of the last set, shown beside the field.
    pub error: Option<String>,
}

/// The link as the window knows it.
#[derive(Debug, Clone, PartialEq)]
pub enum LinkState {
    /// Not connected yet.
    Connecting,
    /// Up.
    Up,
    /// Lost (why); the worker retries every second.
    Lost(String),
}

/// The central area's pages.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Tab {
    /// Live plots.
    Live,
    /// The friction loop: against position and velocity, with the model.
    Friction,
    /// Jog, move and step test.
    Motion,
    /// Commissioning, feedforward tuning and identification.
    Experiments,
    /// Frequency response: the Bode plot, the margins, the notches.
    Frf,
    /// The position map: measured, shown, applied; `map.enable`.
    Map,
    /// Learning from repetition: the iterations as they converge, the correction applied.
    Learn,
}

/// A long run under way.
#[derive(Debug, Clone, PartialEq)]
pub struct Running {
    /// What (commission, tune-ff, identify).
    pub what: String,
    /// Its stage now.
    pub stage: String,
    /// Device seconds done of the stage.
    pub done: f64,
    /// Device seconds the stage expects.
    pub total: f64,
}

/// The experiments page's inputs (as typed).
#[derive(Debug, Clone)]
pub struct ExperimentInputs {
    /// Commissioning speed \[rad/s\].
    pub speed: String,
    /// The motor file.
    pub motor: String,
    /// Sine amplitude \[rad\].
    pub amp: String,
    /// Sine frequency \[Hz\].
    pub freq: String,
    /// Each test \[s\].
    pub seconds: String,
    /// Lowest gain.
    pub from: String,
    /// Highest gain.
    pub to: String,
    /// Gains.
    pub steps: String,
    /// The identification's report directory.
    pub report: String,
    /// The identified parameter file.
    pub identified: String,
}

impl Default for ExperimentInputs {
    fn default() -> Self {
        ExperimentInputs {
            speed: "1".into(),
            motor: "motor.toml".into(),
            amp: "2e-3".into(),
            freq: "1".into(),
            seconds: "3".into(),
            from: "0.7".into(),
            to: "1.2".into(),
            steps: "11".into(),
            report: "identify-report".into(),
            identified: "identified.toml".into(),
        }
    }
}

/// A step test's result.
#[derive(Debug, Clone)]
pub struct StepResult {
    /// The step \[rad\].
    pub step: f64,
    /// Device time at the command \[s\].
    pub t0: f64,
    /// Samples from the command: (t − t0 \[s\], error \[counts\]).
    pub error: Vec<[f64; 2]>,
    /// The figures of `gms-tune step-test` (`gms_tune::run::step_figures`).
    pub metrics: gms_ident::trace::Metrics,
}

/// The window.
pub struct App {
    worker: Worker,
    endpoint: String,
    /// The link's state.
    pub link: LinkState,
    /// The parameter tree, in `list` order.
    pub rows: Vec<Row>,
    /// The last `status` text.
    pub status: Option<StatusReply>,
    /// A reply came late since the last `status` (logged once).
    late: bool,
    /// Received samples (the newest last).
    pub samples: VecDeque<TelemetrySample>,
    /// Samples received since the window opened.
    pub received: u64,
    /// Paused: new samples are not added.
    pub paused: bool,
    /// The live plots' span \[s\].
    pub span: f64,
    /// The visible time window of the live plots (device time, s).
    pub visible: (f64, f64),
    /// What happened, newest last.
    pub log: VecDeque<String>,
    move_pos: String,
    move_vel: String,
    jog: String,
    step_size: String,
    step_pending: Option<(f64, f64)>,
    /// The last step test.
    pub step: Option<StepResult>,
    /// The parameter file of Dump and Load file.
    pub file: String,
    /// The CSV of Export visible.
    pub csv: String,
    /// The page shown.
    pub tab: Tab,
    /// The experiments page's inputs.
    pub inputs: ExperimentInputs,
    /// The long run under way.
    pub running: Option<Running>,
    /// The feedforward sweep's points so far (gain, RMS \[counts\]).
    pub ff_points: Vec<[f64; 2]>,
    /// The frequency response's points so far, in frequency order.
    pub frf_points: Vec<gms_bench::frf::Point>,
    /// The frequency-response page's inputs.
    pub frf_inputs: frf::FrfInputs,
    /// The position map page's inputs.
    pub map_inputs: map::MapInputs,
    /// The learning page's inputs.
    pub learn_inputs: learn::LearnInputs,
    /// The learning's iterations so far.
    pub learn_points: Vec<gms_bench::ilc::Iteration>,
    /// The last long run's result, or why it failed.
    pub outcome: Option<Result<Outcome, String>>,
}

impl App {
    /// A window on `endpoint`; `ctx` is woken by the worker when something arrives; `first`
    /// are request lines sent once the link is first up.
    pub fn new(
        endpoint: Endpoint,
        timeout: Duration,
        first: Vec<String>,
        ctx: &egui::Context,
    ) -> App {
        let c = ctx.clone();
        let label = endpoint.to_string();
        App {
            worker: Worker::start(endpoint, timeout, first, move || c.request_repaint()),
            endpoint: label,
            link: LinkState::Connecting,
            rows: Vec::new(),
            status: None,
            late: false,
            samples: VecDeque::new(),
            received: 0,
            paused: false,
            span: 5.0,
            visible: (0.0, 0.0),
            log: VecDeque::new(),
            move_pos: "0".into(),
            move_vel: "1".into(),
            jog: "1e-3".into(),
            step_size: "2e-4".into(),
            step_pending: None,
            step: None,
            file: "params.toml".into(),
            csv: "live.csv".into(),
            tab: Tab::Live,
            inputs: ExperimentInputs::default(),
            running: None,
            ff_points: Vec::new(),
            frf_points: Vec::new(),
            frf_inputs: frf::FrfInputs::default(),
            map_inputs: map::MapInputs::default(),
            learn_inputs: learn::LearnInputs::default(),
            learn_points: Vec::new(),
            outcome: None,
        }
    }

    /// Starts a long run (one at a time).
    pub fn start(&mut self, what: &str, job: Job) {
        if self.running.is_some() {
            return;
        }
        self.running = Some(Running {
            what: what.into(),
            stage: what.into(),
            done: 0.0,
            total: 0.0,
        });
        self.ff_points.clear();
        self.frf_points.clear();
        self.learn_points.clear();
        self.outcome = None;
        self.note(format!("{what}: started"));
        self.send(Cmd::Run(job));
    }

    /// Ends the long run under way (the worker's stop flag).
    pub fn stop(&mut self) {
        self.worker
            .stop
            .store(true, std::sync::atomic::Ordering::SeqCst);
    }

    fn send(&mut self, c: Cmd) {
        let _ = self.worker.tx.send(c);
    }

    fn note(&mut self, line: String) {
        if self.log.len() == 200 {
            self.log.pop_front();
        }
        self.log.push_back(line);
    }

    /// The device's encoder resolution \[rad/count\]: 2π / its `enc.counts_per_rev` as listed
    /// (the device's default until the list has come).
    pub fn rad_per_count(&self) -> f64 {
        self.rows
            .iter()
            .find(|r| r.listed.path == ParamId::EncCountsPerRev.path())
            .and_then(|r| r.listed.number)
            .filter(|c| c.is_finite() && *c > 0.0)
            .map_or(
                gms_core::device::default_settings().rad_per_count() as f64,
                |c| std::f64::consts::TAU / c,
            )
    }

    /// Takes in what the worker reported.
    pub fn poll(&mut self) {
        while let Ok(e) = self.worker.rx.try_recv() {
            match e {
                Event::Connected => {
                    self.link = LinkState::Up;
                    self.note(format!("link up ({})", self.endpoint));
                }
                Event::Lost(why) => {
                    if self.link != LinkState::Lost(why.clone()) {
                        self.note(format!("link lost: {why}"));
                    }
                    self.link = LinkState::Lost(why);
                }
                Event::Late(why) => {
                    // Once per episode: a run of late replies is one line in the log.
                    if !self.late {
                        self.note(format!("device slow: {why} (the link is kept)"));
                    }
                    self.late = true;
                }
                Event::Listed(v) => {
                    self.rows = v
                        .into_iter()
                        .map(|l| Row {
                            edit: l.value.clone(),
                            listed: l,
                            error: None,
                        })
                        .collect();
                }
                Event::Set {
                    path,
                    result,
                    value,
                } => {
                    if let Some(r) = self.rows.iter_mut().find(|r| r.listed.path == path) {
                        r.error = result.as_ref().err().cloned();
                        if let Some(v) = value {
                            r.listed.value = v.clone();
                            r.edit = v;
                        } else {
                            r.edit = r.listed.value.clone();
                        }
                    }
                    match result {
                        Ok(()) => self.note(format!("set {path}: ok")),
                        Err(e) => self.note(format!("set {path}: {e}")),
                    }
                }
                Event::Reply { line, result } => match result {
                    Ok(t) if t.is_empty() => self.note(format!("{line}: ok")),
                    Ok(t) => self.note(format!("{line}: {t}")),
                    Err(e) => self.note(format!("{line}: {e}")),
                },
                Event::Status(s) => {
                    self.late = false;
                    self.status = Some(s)
                }
                Event::Progress { stage, done, total } => {
                    if let Some(r) = &mut self.running {
                        (r.stage, r.done, r.total) = (stage, done, total);
                    }
                }
                Event::FfPoint(g, rms) => {
                    let rpc = self.rad_per_count();
                    self.ff_points.push([g, rms / rpc])
                }
                Event::LearnPoint(it) => self.learn_points.push(it),
                Event::FrfPoint(p) => {
                    let at = self.frf_points.partition_point(|q| q.f_hz < p.f_hz);
                    self.frf_points.insert(at, p);
                }
                Event::Done(r) => {
                    let what = self.running.take().map_or(String::new(), |r| r.what);
                    match &r {
                        Ok(_) => self.note(format!("{what}: done")),
                        Err(e) => self.note(format!("{what}: {e}")),
                    }
                    self.outcome = Some(r);
                }
                Event::Samples(v) => {
                    self.received += v.len() as u64;
                    if !self.paused {
                        for s in v {
                            if self.samples.len() == KEEP {
                                self.samples.pop_front();
                            }
                            self.samples.push_back(s);
                        }
                    }
                    self.finish_step();
                }
            }
        }
    }

    /// True while the last `status` says the bridge is on.
    pub fn bridge_on(&self) -> bool {
        self.status.is_some_and(|s| s.enabled)
    }

    /// The whole window.
    pub fn show(&mut self, ui: &mut egui::Ui) {
        self.poll();
        egui::Panel::top("top").show(ui, |ui| self.top_bar(ui));
        egui::Panel::bottom("log")
            .resizable(true)
            .default_size(90.0)
            .show(ui, |ui| self.log_view(ui));
        egui::Panel::left("params")
            .resizable(true)
            .default_size(430.0)
            .show(ui, |ui| self.param_tree(ui));
        egui::CentralPanel::default().show(ui, |ui| {
            ui.horizontal(|ui| {
                ui.selectable_value(&mut self.tab, Tab::Live, "Live");
                ui.selectable_value(&mut self.tab, Tab::Friction, "Friction loop");
                ui.selectable_value(&mut self.tab, Tab::Motion, "Motion");
                ui.selectable_value(&mut self.tab, Tab::Experiments, "Experiments");
                ui.selectable_value(&mut self.tab, Tab::Frf, "Frequency response");
                ui.selectable_value(&mut self.tab, Tab::Map, "Position map");
                ui.selectable_value(&mut self.tab, Tab::Learn, "Learning");
            });
            ui.separator();
            match self.tab {
                Tab::Live => self.live(ui),
                Tab::Friction => self.friction(ui),
                Tab::Motion => self.motion(ui),
                Tab::Experiments => self.experiments(ui),
                Tab::Frf => self.frf(ui),
                Tab::Map => self.map(ui),
                Tab::Learn => self.learn(ui),
            }
        });
        // Telemetry arrives continuously: a smooth frame rate while the link is up.
        ui.ctx().request_repaint_after(Duration::from_millis(30));
    }

    fn top_bar(&mut self, ui: &mut egui::Ui) {
        ui.horizontal_wrapped(|ui| {
            match &self.link {
                LinkState::Connecting => {
                    ui.label(format!("connecting to {} …", self.endpoint));
                }
                LinkState::Up => {
                    ui.label(
                        RichText::new(format!("link up: {}", self.endpoint)).color(Color32::GREEN),
                    );
                }
                LinkState::Lost(why) => {
                    ui.label(
                        RichText::new(format!("link lost: {why} (retrying)"))
                            .color(Color32::from_rgb(255, 90, 90))
                            .strong(),
                    );
                }
            }
            ui.separator();
            for (label, c) in [
                ("Enable", Command::Enable { current: false }),
                ("Disable", Command::Disable),
                ("Clear", Command::Clear),
                ("Save", Command::Save),
                ("Load", Command::Load),
                ("Defaults", Command::Defaults),
            ] {
                if ui.button(label).clicked() {
                    self.send(Cmd::Send(c));
                }
            }
            ui.separator();
            ui.label(if self.bridge_on() {
                "bridge on"
            } else {
                "bridge off"
            });
            let mut names = String::from("none");
            if let Some(st) = self.status {
                ui.label(format!("drive {}", st.drive.name()));
                ui.label(format!("pos {:.6} rad", st.pos));
                ui.label(format!("error {} counts", st.error_counts));
                names = gms_bench::fault_names(st.faults);
            }
            if names == "none" {
                ui.label("faults: none");
            } else {
                for n in names.split(',') {
                    let meaning = gms_core::drive::Faults::meaning(n).unwrap_or("unknown fault");
                    ui.label(
                        RichText::new(format!("fault {n}")).color(Color32::from_rgb(255, 90, 90)),
                    )
                    .on_hover_text(meaning);
                }
            }
        });
    }

    fn log_view(&mut self, ui: &mut egui::Ui) {
        egui::ScrollArea::vertical()
            .stick_to_bottom(true)
            .auto_shrink([false, false])
            .show(ui, |ui| {
                for l in &self.log {
                    ui.monospace(l);
                }
            });
    }
}

/// A typed number, or a one-line error naming the field.
/// A labelled text field of `width` points (the label names it for a screen reader and
/// for the window's tests).
fn field(ui: &mut egui::Ui, label: &str, v: &mut String, width: f32) {
    let l = ui.label(label);
    ui.add(egui::TextEdit::singleline(v).desired_width(width))
        .labelled_by(l.id);
}

fn num(text: &str, what: &str) -> Result<f64, String> {
    text.trim()
        .parse::<f64>()
        .ok()
        .filter(|v| v.is_finite())
        .ok_or_else(|| format!("{what} {text:?}: not a number"))
}

/// The feedforward sweep: RMS error against the gain, the chosen gain marked.
fn ff_plot(ui: &mut egui::Ui, pts: Vec<[f64; 2]>, chosen: Option<f64>) {
    let h = (ui.available_height() - 10.0).max(100.0);
    Plot::new("ff")
        .height(h)
        .x_axis_label(ParamId::FfGain.path())
        .y_axis_label("sine test RMS error [counts]")
        .show(ui, |p| {
            p.line(Line::new("RMS error", PlotPoints::from(pts)));
            if let Some(g) = chosen {
                p.vline(egui_plot::VLine::new("chosen", g));
            }
        });
}

/// A path's group in the tree: what comes before its first dot.
fn group(path: &str) -> &str {
    path.split('.').next().unwrap_or(path)
}

/// Decimates `points` (sorted by x) to at most about `2 × buckets` points, keeping each
/// bucket's lowest and highest point in their order: no peak is lost.
pub fn decimate(points: &[[f64; 2]], buckets: usize) -> Vec<[f64; 2]> {
    if points.len() <= 2 * buckets.max(1) {
        return points.to_vec();
    }
    let per = points.len().div_ceil(buckets.max(1));
    let mut out = Vec::with_capacity(2 * buckets + 2);
    for chunk in points.chunks(per) {
        let (mut lo, mut hi) = (0, 0);
        for (i, p) in chunk.iter().enumerate() {
            if p[1] < chunk[lo][1] {
                lo = i;
            }
            if p[1] > chunk[hi][1] {
                hi = i;
            }
        }
        let (a, b) = if lo <= hi { (lo, hi) } else { (hi, lo) };
        out.push(chunk[a]);
        if b != a {
            out.push(chunk[b]);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decimation_keeps_every_peak() {
        // 100 000 points of noise-free sine with one spike each way.
        let mut pts: Vec<[f64; 2]> = (0..100_000)
            .map(|i| {
                let t = i as f64 * 1e-3;
                [t, (t * 3.0).sin()]
            })
            .collect();
        pts[31_415][1] = 7.0;
        pts[77_777][1] = -9.0;
        let d = decimate(&pts, 800);
        assert!(d.len() <= 1600 + 2, "{}", d.len());
        let max = d.iter().map(|p| p[1]).fold(f64::MIN, f64::max);
        let min = d.iter().map(|p| p[1]).fold(f64::MAX, f64::min);
        assert_eq!((max, min), (7.0, -9.0));
        // In time order.
        assert!(d.windows(2).all(|w| w[0][0] < w[1][0]));
        // Short series pass through.
        assert_eq!(decimate(&pts[..10], 800), pts[..10].to_vec());
    }
}
