//! The Experiments tab: identification, feedforward tuning and commissioning as jobs, their
//! progress and their results.

use super::*;

impl App {
    pub(super) fn experiments(&mut self, ui: &mut egui::Ui) {
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
                    Ok(gms_bench::TuneFfPlan {
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
                            path: ParamId::FfGain.path().into(),
                            value: format!("{}", t.chosen),
                        });
                    }
                });
                let pts = t.curve.iter().map(|(g, r)| [*g, r / rpc]).collect();
                ff_plot(ui, pts, Some(t.chosen));
            }
            Some(Ok(Outcome::Frf { .. })) => {
                ui.label("The frequency response is on the Frequency response page.");
            }
            Some(Ok(Outcome::Map { .. })) => {
                ui.label("The position map is on the Position map page.");
            }
            Some(Ok(Outcome::Learned(_))) => {
                ui.label("The learning is on the Learning page.");
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
    pub(super) fn finish_step(&mut self) {
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
        let rec: Vec<&TelemetrySample> = self.samples.iter().filter(|s| s.t > t0).collect();
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
