//! The Motion tab: jog, move, and the step test with its figures.

use super::*;

impl App {
    /// `move POS [VEL]` to `pos` \[rad\] at the speed typed in the move field (none: the
    /// device's own); a speed that is not a positive number is refused with a note.
    fn move_to(&mut self, pos: f64) {
        let v = self.move_vel.trim();
        let vel = if v.is_empty() {
            None
        } else {
            match v.parse::<f32>() {
                Ok(x) if x.is_finite() && x > 0.0 => Some(x),
                _ => {
                    self.note(format!("move: {v:?} is not a speed"));
                    return;
                }
            }
        };
        self.send(Cmd::Send(Command::Move {
            pos: pos as f32,
            vel,
        }));
    }

    pub(super) fn motion(&mut self, ui: &mut egui::Ui) {
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
                    self.move_to(p + sign * j);
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
                match self.move_pos.trim().parse::<f64>() {
                    Ok(p) if p.is_finite() => self.move_to(p),
                    _ => self.note(format!(
                        "move: {:?} is not a position",
                        self.move_pos.trim()
                    )),
                }
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
                self.send(Cmd::Send(Command::Move {
                    pos: (p + d) as f32,
                    vel: None,
                }));
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
}
