//! The Friction tab: the device's friction model and the measured points under it.

use super::*;

impl App {
    pub(super) fn friction(&mut self, ui: &mut egui::Ui) {
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
        .and_then(|p| gms_core::friction::gms::Gms::try_new(p).ok());
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
}
