//! The Learning page: learning from repetition as a job (`gms-tune learn`'s code): the RMS and
//! peak error of each iteration plotted as they come, then the error over the period at the
//! first pass and the last iteration, and Apply (the best correction left playing).

use gms_bench::learn::{LearnPlan, Path};

use super::*;

/// The page's inputs, as typed.
#[derive(Debug, Clone, PartialEq)]
pub struct LearnInputs {
    /// The sine's amplitude \[rad\].
    pub amplitude: String,
    /// Its frequency \[Hz\].
    pub freq: String,
    /// Learning updates.
    pub iterations: String,
    /// The learning gain [-].
    pub gain: String,
    /// The Q filter's corner \[Hz\].
    pub q_hz: String,
}

impl Default for LearnInputs {
    fn default() -> LearnInputs {
        let p = LearnPlan::default();
        let (a, f) = match p.path {
            Path::Sine { amplitude, freq } => (amplitude, freq),
            Path::Trajectory(_) => (0.05, 1.0),
        };
        LearnInputs {
            amplitude: a.to_string(),
            freq: f.to_string(),
            iterations: p.iterations.to_string(),
            gain: p.gain.to_string(),
            q_hz: p.q_hz.to_string(),
        }
    }
}

impl App {
    pub(super) fn learn(&mut self, ui: &mut egui::Ui) {
        let idle = self.running.is_none();
        let mut start = None;
        ui.horizontal_wrapped(|ui| {
            let inp = &mut self.learn_inputs;
            field(ui, "amplitude [rad]", &mut inp.amplitude, 50.0);
            field(ui, "frequency [Hz]", &mut inp.freq, 50.0);
            field(ui, "iterations", &mut inp.iterations, 50.0);
            field(ui, "gain", &mut inp.gain, 50.0);
            field(ui, "Q [Hz]", &mut inp.q_hz, 50.0);
            if ui.add_enabled(idle, egui::Button::new("Learn")).clicked() {
                start = Some((|| {
                    let plan = LearnPlan {
                        path: Path::Sine {
                            amplitude: num(&inp.amplitude, "amplitude")?,
                            freq: num(&inp.freq, "frequency")?,
                        },
                        iterations: inp.iterations.trim().parse().map_err(|_| {
                            format!("iterations {}: a whole number", inp.iterations)
                        })?,
                        gain: num(&inp.gain, "gain")?,
                        q_hz: num(&inp.q_hz, "Q")?,
                        ..LearnPlan::default()
                    };
                    plan.check().map_err(|e| e.to_string())?;
                    Ok::<_, String>(plan)
                })());
            }
            if !idle && ui.button("Stop").clicked() {
                self.stop();
            }
        });
        match start {
            Some(Ok(plan)) => self.start("learn", Job::Learn(plan)),
            Some(Err(e)) => self.note(format!("learn: {e}")),
            None => {}
        }
        if let Some(r) = &self.running {
            ui.label(format!(
                "{}: {:.1} of about {:.1} s of device time",
                r.stage, r.done, r.total
            ));
        }
        if let Some(last) = self.learn_points.last() {
            let first = self.learn_points[0];
            ui.label(format!(
                "iteration {}: RMS {:.3} counts, peak {:.2} counts (first pass {:.3}, {:.2})",
                last.n, last.rms, last.peak, first.rms, first.peak
            ));
        }
        let mut apply = None;
        let h = ((ui.available_height() - 40.0) / 2.0).max(80.0);
        let series = |f: fn(&gms_bench::ilc::Iteration) -> f64| -> Vec<[f64; 2]> {
            self.learn_points
                .iter()
                .map(|i| [i.n as f64, f(i)])
                .collect()
        };
        let (rms, peak) = (series(|i| i.rms), series(|i| i.peak));
        Plot::new("learn_iterations")
            .height(h)
            .legend(Legend::default())
            .x_axis_label("iteration")
            .y_axis_label("error [counts]")
            .show(ui, |p| {
                // Each series' line and points under one name and colour: one legend entry.
                let (c_rms, c_peak) = (
                    Color32::from_rgb(30, 90, 200),
                    Color32::from_rgb(220, 120, 30),
                );
                p.line(Line::new("RMS", PlotPoints::from(rms.clone())).color(c_rms));
                p.points(
                    Points::new("RMS", PlotPoints::from(rms))
                        .radius(3.0)
                        .color(c_rms),
                );
                p.line(Line::new("peak", PlotPoints::from(peak.clone())).color(c_peak));
                p.points(
                    Points::new("peak", PlotPoints::from(peak))
                        .radius(3.0)
                        .color(c_peak),
                );
            });
        match &self.outcome {
            Some(Ok(Outcome::Learned(l))) => {
                if let Some(s) = l.stopped {
                    ui.label(format!(
                        "stopped: {s:?} (the error grew); the best correction kept"
                    ));
                }
                if let Some(r) = l.repeat() {
                    ui.label(r.line());
                }
                if ui.button("Apply the correction").clicked() {
                    apply = Some(l.correction.clone());
                }
                let dt = l.table.as_ref().map_or(1e-3, |t| t.dt());
                let trace = |e: &[f64]| -> Vec<[f64; 2]> {
                    e.iter()
                        .enumerate()
                        .map(|(k, v)| [k as f64 * dt, *v])
                        .collect()
                };
                let first = l.errors.first().map(|e| trace(e)).unwrap_or_default();
                let last = l.errors.last().map(|e| trace(e)).unwrap_or_default();
                Plot::new("learn_period")
                    .height(h)
                    .legend(Legend::default())
                    .x_axis_label("time in the period [s]")
                    .y_axis_label("error [counts]")
                    .show(ui, |p| {
                        p.line(Line::new("first pass", PlotPoints::from(first)));
                        p.line(Line::new("last iteration", PlotPoints::from(last)));
                    });
            }
            Some(Err(e)) => {
                ui.label(RichText::new(e).color(Color32::from_rgb(255, 90, 90)));
            }
            _ if self.learn_points.is_empty() => {
                ui.label(
                    "Learn: the sine x = A (1 − cos 2πft) from where the axis holds, played from \
                     the device's tables; after each period the feedforward correction is learned \
                     from its error. Apply leaves the best correction playing for the next runs.",
                );
            }
            _ => {}
        }
        if let Some(u) = apply {
            self.send(Cmd::UseCorrection(u));
        }
    }
}
