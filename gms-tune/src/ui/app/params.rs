//! The Parameters tab: the device's parameter table as a tree, edited in place.

use super::*;

impl App {
    pub(super) fn param_tree(&mut self, ui: &mut egui::Ui) {
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
}
