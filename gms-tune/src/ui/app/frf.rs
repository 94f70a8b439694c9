//! The Frequency response page: a sweep as a job (`gms-tune frf`'s code), its Bode plot as
//! the points arrive, the margins marked, and beside it the device's notches with the one
//! proposed for the open loop and its effect on the plot.

use egui_plot::VLine;
use gms_bench::frf::{Loop, MIN_COHERENCE, Plan, Point};

use super::*;

/// The page's inputs, as typed.
#[derive(Debug, Clone, PartialEq)]
pub struct FrfInputs {
    /// `plant`, `open` or `closed`.
    pub lp: Loop,
    /// Lowest frequency \[Hz\].
    pub from: String,
    /// Highest frequency \[Hz\].
    pub to: String,
    /// Points.
    pub points: String,
    /// Amplitude (A, or rad for the closed loop); empty: the default.
    pub amplitude: String,
    /// Speed while measuring \[rad/s\]; empty: at rest.
    pub velocity: String,
}

impl Default for FrfInputs {
    fn default() -> FrfInputs {
        FrfInputs {
            lp: Loop::Open,
            from: "10".into(),
            to: "3000".into(),
            points: "40".into(),
            amplitude: String::new(),
            velocity: String::new(),
        }
    }
}

/// `(log10 f, value)` pairs for a plot whose x axis is the frequency's logarithm.
fn log_points(pts: &[Point], y: impl Fn(&Point) -> f64) -> Vec<[f64; 2]> {
    pts.iter().map(|p| [p.f_hz.log10(), y(p)]).collect()
}

impl App {
    /// The plan the inputs describe (the amplitude's default: 1 % of `lim.i_max` at the
    /// current, 20 counts at the reference).
    fn frf_plan(&self) -> Result<Plan, String> {
        let inp = &self.frf_inputs;
        let listed = |p: ParamId| {
            self.rows
                .iter()
                .find(|r| r.listed.path == p.path())
                .and_then(|r| r.listed.number)
        };
        let amp = if inp.amplitude.trim().is_empty() {
            match inp.lp {
                Loop::Closed => 20.0 * self.rad_per_count(),
                _ => 0.01 * listed(ParamId::LimIMax).unwrap_or(0.5),
            }
        } else {
            num(&inp.amplitude, "amplitude")?
        };
        let mut plan = Plan::new(inp.lp, amp);
        plan.from_hz = num(&inp.from, "from")?;
        plan.to_hz = num(&inp.to, "to")?;
        plan.points = inp
            .points
            .trim()
            .parse()
            .map_err(|_| format!("points {}: a whole number", inp.points))?;
        if !inp.velocity.trim().is_empty() {
            plan.velocity = Some(num(&inp.velocity, "velocity")?);
        }
        plan.check(
            listed(ParamId::RatePosHz).unwrap_or(10_000.0),
            listed(ParamId::LimIMax).unwrap_or(0.5),
        )
        .map_err(|e| e.to_string())?;
        Ok(plan)
    }

    pub(super) fn frf(&mut self, ui: &mut egui::Ui) {
        let idle = self.running.is_none();
        let mut start = None;
        // Wrapped: on a narrow window the buttons go to a second row rather than off its edge.
        ui.horizontal_wrapped(|ui| {
            let inp = &mut self.frf_inputs;
            for (lp, name) in [
                (Loop::Plant, "plant"),
                (Loop::Open, "open loop"),
                (Loop::Closed, "closed loop"),
            ] {
                ui.selectable_value(&mut inp.lp, lp, name);
            }
            field(ui, "from [Hz]", &mut inp.from, 50.0);
            field(ui, "to [Hz]", &mut inp.to, 50.0);
            field(ui, "points", &mut inp.points, 50.0);
            field(ui, "amplitude", &mut inp.amplitude, 50.0);
            field(ui, "speed [rad/s]", &mut inp.velocity, 50.0);
            if ui.add_enabled(idle, egui::Button::new("Measure")).clicked() {
                start = Some(());
            }
            if !idle && ui.button("Stop").clicked() {
                self.stop();
            }
        });
        if start.is_some() {
            match self.frf_plan() {
                Ok(plan) => self.start("frf", Job::Frf(plan)),
                Err(e) => self.note(format!("frf: {e}")),
            }
        }
        if let Some(r) = &self.running {
            ui.label(format!(
                "{}: {:.1} of about {:.1} s of device time",
                r.stage, r.done, r.total
            ));
        }
        // The result: margins, the notch proposed, the device's filters.
        let mut apply = None;
        let mut predicted: Vec<Point> = Vec::new();
        let mut marks: Vec<(f64, String)> = Vec::new();
        if let Some(Ok(Outcome::Frf {
            sweep,
            suggestion,
            shaping,
        })) = &self.outcome
        {
            for l in
                crate::run::frf_summary(sweep, suggestion.as_ref().and_then(|s| s.as_ref().ok()))
            {
                ui.label(l);
            }
            if let Some(m) = &sweep.margins {
                marks.push((m.crossover_hz, "crossover".into()));
                marks.push((m.phase_margin_hz, format!("PM {:.0}°", m.phase_margin_deg)));
                marks.push((m.gain_margin_hz, format!("GM {:.1} dB", m.gain_margin_db)));
            }
            ui.horizontal(|ui| {
                for (i, n) in shaping.notch.iter().enumerate() {
                    ui.label(if n.f_hz > 0.0 {
                        format!(
                            "filt.notch{}: {:.1} Hz, q {}, {} dB",
                            i + 1,
                            n.f_hz,
                            n.q,
                            n.depth_db
                        )
                    } else {
                        format!("filt.notch{}: off", i + 1)
                    });
                }
                ui.label(if shaping.lp_hz > 0.0 {
                    format!("filt.lp: {:.0} Hz", shaping.lp_hz)
                } else {
                    "filt.lp: off".into()
                });
            });
            match suggestion {
                Some(Ok(s)) => {
                    // The loop gain with the proposed notch: the measurement times its
                    // response.
                    let pos_hz = self
                        .rows
                        .iter()
                        .find(|r| r.listed.path == ParamId::RatePosHz.path())
                        .and_then(|r| r.listed.number)
                        .unwrap_or(10_000.0);
                    let p = gms_core::control::shaping::ShapingParams {
                        notch: [s.notch, gms_core::control::shaping::Notch::OFF],
                        lp_hz: 0.0,
                    };
                    if let Ok(sh) = gms_core::control::shaping::Shaping::try_new(&p, pos_hz as f32)
                    {
                        predicted = sweep
                            .points
                            .iter()
                            .map(|q| {
                                let (re, im) = sh.response(q.f_hz, pos_hz);
                                Point {
                                    value: q.value * num_complex::Complex64::new(re, im),
                                    ..*q
                                }
                            })
                            .collect();
                    }
                    if ui.button("Apply the notch").clicked() {
                        apply = Some(s.sets());
                    }
                }
                Some(Err(e)) => {
                    ui.label(format!("no notch proposed: {e}"));
                }
                None => {}
            }
        } else if let Some(Err(e)) = &self.outcome {
            ui.label(RichText::new(e).color(Color32::from_rgb(255, 90, 90)));
        }
        if let Some(sets) = apply {
            for (path, value) in sets {
                self.send(Cmd::Set { path, value });
            }
        }
        let (good, poor): (Vec<Point>, Vec<Point>) = self
            .frf_points
            .iter()
            .partition(|p| p.coherence >= MIN_COHERENCE);
        let h = ((ui.available_height() - 20.0) / 2.0).max(80.0);
        let axis = |m: egui_plot::GridMark, _: &std::ops::RangeInclusive<f64>| {
            format!("{:.0} Hz", 10f64.powf(m.value))
        };
        let draw = |ui: &mut egui::Ui, id: &str, label: &str, y: &dyn Fn(&Point) -> f64| {
            Plot::new(id.to_string())
                .height(h)
                .legend(Legend::default())
                .x_axis_formatter(axis)
                .y_axis_label(label)
                .show(ui, |p| {
                    p.points(
                        Points::new("measured", PlotPoints::from(log_points(&good, y))).radius(3.0),
                    );
                    if !poor.is_empty() {
                        p.points(
                            Points::new("below the noise", PlotPoints::from(log_points(&poor, y)))
                                .radius(2.0)
                                .color(Color32::GRAY),
                        );
                    }
                    if !predicted.is_empty() {
                        p.line(Line::new(
                            "with the notch proposed",
                            PlotPoints::from(log_points(&predicted, y)),
                        ));
                    }
                    for (f, text) in &marks {
                        if f.is_finite() && *f > 0.0 {
                            p.vline(VLine::new(text.clone(), f.log10()));
                        }
                    }
                });
        };
        draw(ui, "frf_gain", "gain [dB]", &|p: &Point| p.gain_db());
        draw(ui, "frf_phase", "phase [deg]", &|p: &Point| p.phase_deg());
    }
}
