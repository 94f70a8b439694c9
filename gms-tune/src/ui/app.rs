//! The window's state and drawing: what the worker reports, shown; what the user does, sent.
//! Nothing here talks to the device: the worker does ([`super::worker`]).

use std::collections::VecDeque;
use std::path::PathBuf;
use std::time::Duration;

use egui::{Color32, RichText};
use egui_plot::{Legend, Line, Plot, PlotPoints, Points};
use gms_core::device::StatusReply;
use gms_core::model::FrictionModel;

use super::worker::{Cmd, Endpoint, Event, Job, Outcome, Sample, Worker};
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
    /// Received samples (the newest last).
    pub samples: VecDeque<Sample>,
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
            .find(|r| r.listed.path == "enc.counts_per_rev")
            .and_then(|r| r.listed.value.parse::<f64>().ok())
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
                Event::Status(s) => self.status = Some(s),
                Event::Progress { stage, done, total } => {
                    if let Some(r) = &mut self.running {
                        (r.stage, r.done, r.total) = (stage, done, total);
                    }
                }
                Event::FfPoint(g, rms) => {
                    let rpc = self.rad_per_count();
                    self.ff_points.push([g, rms / rpc])
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
            });
            ui.separator();
            match self.tab {
                Tab::Live => self.live(ui),
                Tab::Friction => self.friction(ui),
                Tab::Motion => self.motion(ui),
                Tab::Experiments => self.experiments(ui),
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
            for (label, line) in [
                ("Enable", "enable"),
                ("Disable", "disable"),
                ("Clear", "clear"),
                ("Save", "save"),
                ("Load", "load"),
                ("Defaults", "defaults"),
            ] {
                if ui.button(label).clicked() {
                    self.send(Cmd::Request(line.into()));
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
                names.clear();
                let _ = st.faults.write_names(&mut names);
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

    fn param_tree(&mut self, ui: &mut egui::Ui) {
        ui.heading("Parameters");
        ui.horizontal(|ui| {
            let l = ui.label("file");
            ui.add(egui::TextEdit::singleline(&mut self.file).desired_width(140.0))
                .labelled_by(l.id);
            if ui.button("Dump").clicked() {
                self.send(Cmd::Dump(PathBuf::from(&self.file)));
            }
            if ui.button("Load file").clicked() {
                self.send(Cmd::Load(PathBuf::from(&self.file)));
            }
            if ui.button("Reread").clicked() {
                self.send(Cmd::List);
            }
        });
        ui.separator();
        let mut sets = Vec::new();
        egui::ScrollArea::vertical().show(ui, |ui| {
            let mut i = 0;
            while i < self.rows.len() {
                let prefix = group(&self.rows[i].listed.path).to_string();
                let end = self.rows[i..]
                    .iter()
                    .position(|r| group(&r.listed.path) != prefix)
                    .map_or(self.rows.len(), |n| i + n);
                egui::CollapsingHeader::new(&prefix)
                    .default_open(true)
                    .show(ui, |ui| {
                        egui::Grid::new(format!("grid-{prefix}"))
                            .num_columns(4)
                            .striped(true)
                            .show(ui, |ui| {
                                for r in &mut self.rows[i..end] {
                                    let label = ui.label(&r.listed.path);
                                    let ro = r.listed.read_only();
                                    let edit = ui
                                        .add_enabled(
                                            !ro,
                                            egui::TextEdit::singleline(&mut r.edit)
                                                .id_salt(&r.listed.path)
                                                .desired_width(130.0)
                                                .min_size(egui::vec2(130.0, 0.0)),
                                        )
                                        .labelled_by(label.id);
                                    if edit.lost_focus()
                                        && ui.input(|i| i.key_pressed(egui::Key::Enter))
                                        && r.edit.trim() != r.listed.value
                                    {
                                        sets.push((
                                            r.listed.path.clone(),
                                            r.edit.trim().to_string(),
                                        ));
                                    }
                                    ui.label(&r.listed.unit);
                                    ui.label(RichText::new(&r.listed.range).weak());
                                    if let Some(e) = &r.error {
                                        ui.label(
                                            RichText::new(e).color(Color32::from_rgb(255, 90, 90)),
                                        );
                                    }
                                    ui.end_row();
                                }
                            });
                    });
                i = end;
            }
        });
        for (path, value) in sets {
            self.send(Cmd::Set { path, value });
        }
    }

    /// The samples in the live window (all of the span when running; the paused view when
    /// paused).
    fn window(&self) -> Vec<Sample> {
        let Some(last) = self.samples.back() else {
            return Vec::new();
        };
        let from = last.t - self.span;
        self.samples
            .iter()
            .filter(|s| s.t >= from)
            .copied()
            .collect()
    }

    fn live(&mut self, ui: &mut egui::Ui) {
        let rpc = self.rad_per_count();
        ui.horizontal(|ui| {
            let label = if self.paused { "Resume" } else { "Pause" };
            if ui.button(label).clicked() {
                self.paused = !self.paused;
            }
            ui.add(
                egui::Slider::new(&mut self.span, 0.5..=60.0)
                    .text("span [s]")
                    .logarithmic(true),
            );
            let l = ui.label("CSV");
            ui.add(egui::TextEdit::singleline(&mut self.csv).desired_width(120.0))
                .labelled_by(l.id);
            if ui.button("Export visible").clicked() {
                let msg = self.export(&PathBuf::from(&self.csv));
                self.note(msg);
            }
            ui.label(format!("{} samples received", self.received));
        });
        let w = self.window();
        let width = ui.available_width().max(100.0) as usize;
        let h = ((ui.available_height() - 20.0) / 4.0).max(60.0);
        let link = ui.make_persistent_id("live-x");
        let series = |f: &dyn Fn(&Sample) -> f64| -> Vec<[f64; 2]> {
            decimate(&w.iter().map(|s| [s.t, f(s)]).collect::<Vec<_>>(), width)
        };
        let resp = Plot::new("pos")
            .height(h)
            .link_axis(link, [true, false])
            .legend(Legend::default())
            .y_axis_label("rad")
            .show(ui, |p| {
                p.line(Line::new(
                    "reference",
                    PlotPoints::from(series(&|s| s.reference)),
                ));
                p.line(Line::new("position", PlotPoints::from(series(&|s| s.pos))));
            });
        let b = resp.transform.bounds();
        self.visible = (b.min()[0], b.max()[0]);
        Plot::new("error")
            .height(h)
            .link_axis(link, [true, false])
            .legend(Legend::default())
            .y_axis_label("counts")
            .show(ui, |p| {
                p.line(Line::new(
                    "error [counts]",
                    PlotPoints::from(series(&|s| s.error / rpc)),
                ));
            });
        Plot::new("friction")
            .height(h)
            .link_axis(link, [true, false])
            .legend(Legend::default())
            .y_axis_label("N·m")
            .show(ui, |p| {
                p.line(Line::new(
                    "feedforward",
                    PlotPoints::from(series(&|s| s.ff)),
                ));
                p.line(Line::new(
                    "friction (estimate)",
                    PlotPoints::from(series(&|s| s.friction)),
                ));
            });
        Plot::new("current")
            .height(h)
            .link_axis(link, [true, false])
            .legend(Legend::default())
            .y_axis_label("A")
            .x_axis_label("device time [s]")
            .show(ui, |p| {
                p.line(Line::new(
                    "current",
                    PlotPoints::from(series(&|s| s.current)),
                ));
            });
    }

    /// Writes the samples of the visible time window as CSV; returns what happened.
    pub fn export(&self, path: &std::path::Path) -> String {
        let (a, b) = self.visible;
        let mut text = String::from("t,pos,ref,error,ff,current,friction\n");
        let mut n = 0;
        for s in self.samples.iter().filter(|s| s.t >= a && s.t <= b) {
            text.push_str(&format!(
                "{},{},{},{},{},{},{}\n",
                s.t, s.pos, s.reference, s.error, s.ff, s.current, s.friction
            ));
            n += 1;
        }
        match std::fs::write(path, text) {
            Ok(()) => format!(
                "{n} samples ({a:.3} to {b:.3} s) written to {}",
                path.display()
            ),
            Err(e) => format!("{}: {e}", path.display()),
        }
    }

    fn friction(&mut self, ui: &mut egui::Ui) {
        let w = self.window();
        let model = crate::params::to_file(
            &self
                .rows
                .iter()
                .map(|r| r.listed.clone())
                .collect::<Vec<_>>(),
        )
        .ok()
        .and_then(|pf| pf.friction.gms_params::<6>().ok())
        .and_then(|p| gms_core::gms::Gms::try_new(p).ok());
        ui.label(format!(
            "The last {:.1} s of telemetry: the friction estimate (k_M·i − J·a_ref) against the \
             position (pre-sliding hysteresis) and the velocity (Stribeck curve), with the \
             device's GMS model over it (run along the same positions; its steady curve).",
            self.span
        ));
        let h = (ui.available_height() - 10.0).max(100.0);
        ui.columns(2, |cols| {
            let pts: Vec<[f64; 2]> = w.iter().map(|s| [s.pos, s.friction]).collect();
            let modelled: Option<Vec<[f64; 2]>> = model.clone().map(|mut g| {
                let mut out = Vec::with_capacity(w.len());
                for p in w.windows(2) {
                    let f = g.advance((p[1].pos - p[0].pos) as f32, (p[1].t - p[0].t) as f32);
                    out.push([p[1].pos, f as f64]);
                }
                out
            });
            Plot::new("fx")
                .height(h)
                .legend(Legend::default())
                .x_axis_label("position [rad]")
                .y_axis_label("friction [N·m]")
                .show(&mut cols[0], |p| {
                    p.points(Points::new("measured", PlotPoints::from(pts)).radius(1.0));
                    if let Some(m) = modelled {
                        p.line(Line::new("model", PlotPoints::from(m)));
                    }
                });
            let vel: Vec<[f64; 2]> = w
                .windows(11)
                .map(|p| {
                    let (a, b) = (&p[0], &p[10]);
                    [(b.pos - a.pos) / (b.t - a.t).max(1e-9), p[5].friction]
                })
                .collect();
            let vmax = vel.iter().map(|p| p[0].abs()).fold(0.0, f64::max).max(0.01);
            let curve: Option<Vec<[f64; 2]>> = model.map(|g| {
                let sigma = g.params().sigma as f64;
                (-200..=200)
                    .map(|k| {
                        let v = vmax * k as f64 / 200.0;
                        [v, g.stribeck().value(v as f32) as f64 + sigma * v]
                    })
                    .collect()
            });
            Plot::new("fv")
                .height(h)
                .legend(Legend::default())
                .x_axis_label("velocity [rad/s]")
                .y_axis_label("friction [N·m]")
                .show(&mut cols[1], |p| {
                    p.points(Points::new("measured", PlotPoints::from(vel)).radius(1.0));
                    if let Some(c) = curve {
                        p.line(Line::new("model s(v) + σv", PlotPoints::from(c)));
                    }
                });
        });
    }

    fn motion(&mut self, ui: &mut egui::Ui) {
        let rpc = self.rad_per_count();
        let pos = self.status.map(|s| s.pos);
        ui.horizontal(|ui| {
            let l = ui.label("jog [rad]");
            ui.add(egui::TextEdit::singleline(&mut self.jog).desired_width(70.0))
                .labelled_by(l.id);
            for (label, sign) in [("Jog −", -1.0), ("Jog +", 1.0)] {
                if ui.button(label).clicked()
                    && let (Some(p), Ok(j)) = (pos, self.jog.trim().parse::<f64>())
                {
                    self.send(Cmd::Request(format!(
                        "move {} {}",
                        p + sign * j,
                        self.move_vel.trim()
                    )));
                }
            }
        });
        ui.horizontal(|ui| {
            let l = ui.label("move to [rad]");
            ui.add(egui::TextEdit::singleline(&mut self.move_pos).desired_width(90.0))
                .labelled_by(l.id);
            let l = ui.label("at [rad/s]");
            ui.add(egui::TextEdit::singleline(&mut self.move_vel).desired_width(60.0))
                .labelled_by(l.id);
            if ui.button("Move").clicked() {
                self.send(Cmd::Request(format!(
                    "move {} {}",
                    self.move_pos.trim(),
                    self.move_vel.trim()
                )));
            }
        });
        ui.separator();
        ui.horizontal(|ui| {
            let l = ui.label("step test [rad]");
            ui.add(egui::TextEdit::singleline(&mut self.step_size).desired_width(70.0))
                .labelled_by(l.id);
            if ui.button("Step").clicked()
                && let (Some(p), Ok(d), Some(last)) = (
                    pos,
                    self.step_size.trim().parse::<f64>(),
                    self.samples.back(),
                )
            {
                self.step_pending = Some((d, last.t));
                self.send(Cmd::Request(format!("move {}", p + d)));
            }
        });
        if let Some(s) = &self.step {
            let m = &s.metrics;
            ui.label(format!(
                "step {:.3e} rad: {} within ±1 count {:.1} ms after the move, steady-state \
                 error {:.2} counts, largest error {:.1} counts (the figures of gms-tune \
                 step-test)",
                s.step,
                if m.unsettled_steps > 0.0 {
                    "not settled"
                } else {
                    "settled"
                },
                m.settle_time * 1e3,
                m.steady_state_error / rpc,
                m.max_error / rpc
            ));
            let h = (ui.available_height() - 10.0).max(100.0);
            let e = s.error.clone();
            Plot::new("step")
                .height(h)
                .x_axis_label("time from the command [s]")
                .y_axis_label("error [counts]")
                .show(ui, |p| p.line(Line::new("error", PlotPoints::from(e))));
        }
    }

    fn experiments(&mut self, ui: &mut egui::Ui) {
        let rpc = self.rad_per_count();
        let idle = self.running.is_none();
        if let Some(r) = &self.running {
            let frac = if r.total > 0.0 {
                (r.done / r.total).clamp(0.0, 1.0) as f32
            } else {
                0.0
            };
            let text = format!(
                "{}: {} — {:.1} of about {:.1} s of device time",
                r.what, r.stage, r.done, r.total
            );
            ui.horizontal(|ui| {
                ui.add(egui::ProgressBar::new(frac).text(text).desired_width(600.0));
                if ui.button("Stop").clicked() {
                    self.stop();
                }
            });
        } else {
            ui.label("One run at a time; the bridge is off when a run ends by a failure or Stop.");
        }
        ui.separator();
        let inp = &mut self.inputs;
        let mut start: Option<(&str, Result<Job, String>)> = None;
        let field = |ui: &mut egui::Ui, label: &str, v: &mut String, w: f32| {
            let l = ui.label(label);
            ui.add(egui::TextEdit::singleline(v).desired_width(w))
                .labelled_by(l.id);
        };
        ui.horizontal(|ui| {
            field(ui, "speed [rad/s]", &mut inp.speed, 50.0);
            field(ui, "motor file", &mut inp.motor, 120.0);
            if ui
                .add_enabled(idle, egui::Button::new("Commission"))
                .clicked()
            {
                let job = num(&inp.speed, "speed").map(|speed| Job::Commission {
                    speed,
                    out: PathBuf::from(&inp.motor),
                });
                start = Some(("commission", job));
            }
        });
        ui.horizontal(|ui| {
            field(ui, "amplitude [rad]", &mut inp.amp, 60.0);
            field(ui, "frequency [Hz]", &mut inp.freq, 40.0);
            field(ui, "seconds", &mut inp.seconds, 40.0);
            field(ui, "gain from", &mut inp.from, 40.0);
            field(ui, "to", &mut inp.to, 40.0);
            field(ui, "steps", &mut inp.steps, 40.0);
            if ui.add_enabled(idle, egui::Button::new("Tune ff")).clicked() {
                let plan = (|| {
                    Ok(gms_ident::bench::TuneFfPlan {
                        amp: num(&inp.amp, "amplitude")?,
                        freq: num(&inp.freq, "frequency")?,
                        seconds: num(&inp.seconds, "seconds")?,
                        from: num(&inp.from, "gain from")?,
                        to: num(&inp.to, "to")?,
                        steps: inp
                            .steps
                            .trim()
                            .parse()
                            .map_err(|_| format!("steps {}: a whole number", inp.steps))?,
                        ..Default::default()
                    })
                })();
                start = Some(("tune-ff", plan.map(Job::TuneFf)));
            }
        });
        ui.horizontal(|ui| {
            field(ui, "report directory", &mut inp.report, 140.0);
            field(ui, "identified file", &mut inp.identified, 140.0);
            if ui
                .add_enabled(idle, egui::Button::new("Identify"))
                .clicked()
            {
                start = Some((
                    "identify",
                    Ok(Job::Identify {
                        report: PathBuf::from(&inp.report),
                        out: PathBuf::from(&inp.identified),
                    }),
                ));
            }
        });
        match start {
            Some((what, Ok(job))) => self.start(what, job),
            Some((what, Err(e))) => self.note(format!("{what}: {e}")),
            None => {}
        }
        ui.separator();
        let mut apply: Option<Cmd> = None;
        match &self.outcome {
            None => {
                if !self.ff_points.is_empty() {
                    let pts = self.ff_points.clone();
                    ff_plot(ui, pts, None);
                }
            }
            Some(Err(e)) => {
                ui.label(RichText::new(e).color(Color32::from_rgb(255, 90, 90)));
            }
            Some(Ok(Outcome::Commissioned { lines, file })) => {
                ui.horizontal(|ui| {
                    if ui.button("Apply the motor settings").clicked() {
                        apply = Some(Cmd::Apply(file.clone()));
                    }
                });
                for l in lines {
                    ui.monospace(l);
                }
            }
            Some(Ok(Outcome::TunedFf(t))) => {
                for l in crate::run::tune_ff_summary(t) {
                    ui.label(l);
                }
                ui.horizontal(|ui| {
                    if ui
                        .add_enabled(t.decided, egui::Button::new("Apply the gain"))
                        .clicked()
                    {
                        apply = Some(Cmd::Set {
                            path: "ff.gain".into(),
                            value: format!("{}", t.chosen),
                        });
                    }
                });
                let pts = t.curve.iter().map(|(g, r)| [*g, r / rpc]).collect();
                ff_plot(ui, pts, Some(t.chosen));
            }
            Some(Ok(Outcome::Identified {
                report,
                presliding,
                sliding,
                file,
            })) => {
                ui.horizontal(|ui| {
                    if ui.button("Apply the identified set").clicked() {
                        apply = Some(Cmd::Apply(file.clone()));
                    }
                });
                egui::ScrollArea::vertical()
                    .max_height(140.0)
                    .show(ui, |ui| {
                        for l in report {
                            ui.monospace(l);
                        }
                    });
                let h = (ui.available_height() - 10.0).max(100.0);
                let pre: Vec<[f64; 2]> = presliding.iter().map(|(x, f)| [*x, *f]).collect();
                let sl: Vec<[f64; 2]> = sliding.iter().map(|(v, f)| [*v, *f]).collect();
                ui.columns(2, |cols| {
                    Plot::new("pre")
                        .height(h)
                        .x_axis_label("pre-sliding displacement [rad]")
                        .y_axis_label("friction [N·m]")
                        .show(&mut cols[0], |p| {
                            p.points(Points::new("virgin curve", PlotPoints::from(pre)).radius(2.0))
                        });
                    Plot::new("slide")
                        .height(h)
                        .x_axis_label("speed [rad/s]")
                        .y_axis_label("friction [N·m]")
                        .show(&mut cols[1], |p| {
                            p.points(Points::new("sliding", PlotPoints::from(sl)).radius(2.0))
                        });
                });
            }
        }
        if let Some(c) = apply {
            self.send(c);
        }
    }

    /// A step test's figures once 0.5 s of samples has come after its command.
    fn finish_step(&mut self) {
        let rpc = self.rad_per_count();
        let Some((d, t0)) = self.step_pending else {
            return;
        };
        let Some(last) = self.samples.back() else {
            return;
        };
        if last.t < t0 + 0.5 {
            return;
        }
        self.step_pending = None;
        let rec: Vec<&Sample> = self.samples.iter().filter(|s| s.t > t0).collect();
        let error: Vec<[f64; 2]> = rec.iter().map(|s| [s.t - t0, s.error / rpc]).collect();
        let rows: Vec<[f64; 6]> = rec
            .iter()
            .map(|s| [s.t, s.reference, s.pos, s.error, s.ff, s.friction])
            .collect();
        let (_, metrics) = crate::run::step_figures(&rows, d, 0.5, rpc);
        self.step = Some(StepResult {
            step: d,
            t0,
            error,
            metrics,
        });
    }
}

/// A typed number, or a one-line error naming the field.
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
        .x_axis_label("ff.gain")
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
