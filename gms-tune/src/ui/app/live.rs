//! The Live tab: the telemetry stream plotted as it arrives, paused, exported.

use super::*;

impl App {
    /// The samples in the live window (all of the span when running; the paused view when
    /// paused).
    pub(super) fn window(&self) -> Vec<TelemetrySample> {
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

    pub(super) fn live(&mut self, ui: &mut egui::Ui) {
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
        let series = |f: &dyn Fn(&TelemetrySample) -> f64| -> Vec<[f64; 2]> {
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
}
