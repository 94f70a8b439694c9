//! The Position map page: a map measured as a job (`gms-tune map`'s code), the torque each way
//! with the offset fitted over it and the friction's scale, Apply, and the device's
//! `map.enable` switch.

use gms_bench::posmap::MapPlan;

use super::*;

/// The page's inputs, as typed.
#[derive(Debug, Clone, PartialEq)]
pub struct MapInputs {
    /// Speed \[rad/s\].
    pub speed: String,
    /// Revolutions each way.
    pub revs: String,
    /// Bins.
    pub bins: String,
}

impl Default for MapInputs {
    fn default() -> MapInputs {
        MapInputs {
            speed: "1".into(),
            revs: "1".into(),
            bins: "512".into(),
        }
    }
}

impl App {
    pub(super) fn map(&mut self, ui: &mut egui::Ui) {
        let idle = self.running.is_none();
        let mut start = None;
        ui.horizontal_wrapped(|ui| {
            let inp = &mut self.map_inputs;
            field(ui, "speed [rad/s]", &mut inp.speed, 50.0);
            field(ui, "revolutions", &mut inp.revs, 50.0);
            field(ui, "bins", &mut inp.bins, 50.0);
            if ui
                .add_enabled(idle, egui::Button::new("Measure the map"))
                .clicked()
            {
                start = Some((|| {
                    let plan = MapPlan {
                        speed: num(&inp.speed, "speed")?,
                        periods: num(&inp.revs, "revolutions")?,
                        bins: inp
                            .bins
                            .trim()
                            .parse()
                            .map_err(|_| format!("bins {}: a whole number", inp.bins))?,
                        ..MapPlan::default()
                    };
                    plan.check().map_err(|e| e.to_string())?;
                    Ok::<_, String>(plan)
                })());
            }
            if !idle && ui.button("Stop").clicked() {
                self.stop();
            }
            // The device's switch, as listed.
            let on = self
                .rows
                .iter()
                .find(|r| r.listed.path == ParamId::MapEnable.path())
                .is_some_and(|r| r.listed.value == "1");
            let mut want = on;
            ui.checkbox(&mut want, "the map acts (map.enable)");
            if want != on {
                self.send(Cmd::Set {
                    path: ParamId::MapEnable.path().into(),
                    value: if want { "1" } else { "0" }.into(),
                });
            }
        });
        match start {
            Some(Ok(plan)) => self.start("map", Job::Map(plan)),
            Some(Err(e)) => self.note(format!("map: {e}")),
            None => {}
        }
        if let Some(r) = &self.running {
            ui.label(format!(
                "{}: {:.1} of about {:.1} s of device time",
                r.stage, r.done, r.total
            ));
        }
        let mut apply = None;
        match &self.outcome {
            Some(Ok(Outcome::Map { data, map })) => {
                let mean = map.offset.iter().sum::<f64>() / map.offset.len().max(1) as f64;
                let rms = (map.offset.iter().map(|o| (o - mean).powi(2)).sum::<f64>()
                    / map.offset.len().max(1) as f64)
                    .sqrt();
                let (lo, hi) = map
                    .scale
                    .iter()
                    .fold((f64::MAX, f64::MIN), |(a, b), k| (a.min(*k), b.max(*k)));
                ui.label(format!(
                    "{} bins: torque ripple {:.3} µN·m RMS; friction scale {lo:.3} … {hi:.3} of the \
                     model's {:.3} µN·m; fit residuals {:.3} / {:.3} µN·m",
                    map.angle.len(),
                    rms * 1e6,
                    map.friction * 1e6,
                    map.residual.0 * 1e6,
                    map.residual.1 * 1e6
                ));
                if ui.button("Apply the map").clicked() {
                    apply = Some(map.clone());
                }
                let period = map.period;
                let every = (data.forward.len() + data.backward.len())
                    .div_ceil(2000)
                    .max(1);
                let pts = |s: &[(f64, f64)]| -> Vec<[f64; 2]> {
                    s.iter()
                        .step_by(every)
                        .map(|(a, t)| [a.rem_euclid(period), t * 1e6])
                        .collect()
                };
                let (fwd, bwd) = (pts(&data.forward), pts(&data.backward));
                let offset: Vec<[f64; 2]> = map
                    .angle
                    .iter()
                    .zip(&map.offset)
                    .map(|(a, o)| [*a, o * 1e6])
                    .collect();
                let scale: Vec<[f64; 2]> = map
                    .angle
                    .iter()
                    .zip(&map.scale)
                    .map(|(a, k)| [*a, *k])
                    .collect();
                let h = ((ui.available_height() - 20.0) / 2.0).max(80.0);
                Plot::new("map_torque")
                    .height(h)
                    .legend(Legend::default())
                    .x_axis_label("angle [rad]")
                    .y_axis_label("torque [µN·m]")
                    .show(ui, |p| {
                        p.points(Points::new("forward", PlotPoints::from(fwd)).radius(1.5));
                        p.points(Points::new("backward", PlotPoints::from(bwd)).radius(1.5));
                        p.line(Line::new("offset (even part)", PlotPoints::from(offset)));
                    });
                Plot::new("map_scale")
                    .height(h)
                    .x_axis_label("angle [rad]")
                    .y_axis_label("friction scale [-]")
                    .show(ui, |p| {
                        p.line(Line::new("scale (odd part)", PlotPoints::from(scale)));
                    });
            }
            Some(Err(e)) => {
                ui.label(RichText::new(e).color(Color32::from_rgb(255, 90, 90)));
            }
            _ => {
                ui.label(
                    "Measure the map: runs both ways over whole revolutions at the speed, the \
                     torque at each angle fitted; the even part is the cogging, the odd part the \
                     friction's scale.",
                );
            }
        }
        if let Some(m) = apply {
            self.send(Cmd::WriteMap(m));
        }
    }
}
