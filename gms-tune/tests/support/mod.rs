//! The end-to-end tests' shared part: the `gms-tune` binary run against a virtual device
//! (`hil_sim::harness::Server`), the window driven by egui_kittest, and one test at a time.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;

pub use hil_sim::harness::{Server, run};

/// The `gms-tune` binary.
pub const TUNE: &str = env!("CARGO_BIN_EXE_gms-tune");

/// Held by each test: one test at a time in a binary (each starts a virtual device, most
/// faster than real time, and two at once on a two-core machine would halve each one's pace).
pub fn one_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    static ONE: std::sync::Mutex<()> = std::sync::Mutex::new(());
    ONE.lock().unwrap_or_else(|p| p.into_inner())
}

/// Runs gms-tune on `link` (`--tcp` or `--port`) to `srv`; returns (exit code, stdout,
/// stderr).
pub fn tune_on(srv: &Server, link: &str, args: &[&str], cwd: &Path) -> (i32, String, String) {
    run(Command::new(TUNE)
        .args([link, &srv.addr])
        .args(args)
        .current_dir(cwd))
}

/// gms-tune over TCP.
pub fn tune(srv: &Server, args: &[&str], cwd: &Path) -> (i32, String, String) {
    tune_on(srv, "--tcp", args, cwd)
}

/// The default plant with its friction exactly nominal (no draw) and the guideway negligible:
/// the device sees the actuator's Table 1 friction alone (`extra` appended to the file).
pub fn quiet_scenario(dir: &Path, extra: &str) -> PathBuf {
    let p = dir.join("scenario.toml");
    std::fs::write(
        &p,
        // The device compensates the actuator alone (its default guideway model off), in
        // the extra's [controller.ff] table when it has one.
        if extra.contains("[controller.ff]\n") {
            format!(
                "[plant]\nvariability = 0.0\n{}\n[plant.guideway]\nfs = 1e-6\nfc = 1e-6\n",
                extra.replacen(
                    "[controller.ff]\n",
                    "[controller.ff]\nguideway = false\n",
                    1
                )
            )
        } else {
            format!(
                "[plant]\nvariability = 0.0\n{extra}\n[plant.guideway]\nfs = 1e-6\nfc = 1e-6\n\
                 [controller.ff]\nguideway = false\n"
            )
        },
    )
    .unwrap();
    p
}

/// The window (`gms_tune::ui::App`, its real widgets driven by egui_kittest without a
/// display) on `srv` over TCP, the harness tall enough to lay out the whole parameter tree.
pub fn window(srv: &Server) -> egui_kittest::Harness<'static, gms_tune::ui::App> {
    window_on(srv, Vec::new())
}

/// The same, the request lines `first` sent once the link is up.
pub fn window_on(
    srv: &Server,
    first: Vec<String>,
) -> egui_kittest::Harness<'static, gms_tune::ui::App> {
    let app = gms_tune::ui::App::new(
        gms_tune::ui::Endpoint::Tcp(srv.addr.clone()),
        std::time::Duration::from_secs(2),
        first,
        &egui::Context::default(),
    );
    egui_kittest::Harness::builder()
        .with_size(egui::vec2(1400.0, 3200.0))
        .build_ui_state(|ui, app: &mut gms_tune::ui::App| app.show(ui), app)
}

/// Steps the window (a frame each 20 ms) until `done` holds, at most `seconds`.
/// (The limit is wall time: pass `srv.wall(DEVICE_SECONDS, HOST_SECONDS)`.)
pub fn step_until(
    h: &mut egui_kittest::Harness<'static, gms_tune::ui::App>,
    seconds: f64,
    done: impl Fn(&gms_tune::ui::App) -> bool,
) -> bool {
    let end = std::time::Instant::now() + std::time::Duration::from_secs_f64(seconds);
    while std::time::Instant::now() < end {
        h.step();
        if done(h.state()) {
            return true;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    false
}

/// Steps the window until `done` holds while a job runs (or after it ended), for at most the
/// wall time `srv` allows for twice the device time the job's stage expects (the window's
/// progress, as it becomes known), plus `extra` seconds of host work; true if it came.
pub fn step_job(
    h: &mut egui_kittest::Harness<'static, gms_tune::ui::App>,
    srv: &Server,
    extra: f64,
    done: impl Fn(&gms_tune::ui::App) -> bool,
) -> bool {
    let start = std::time::Instant::now();
    let mut expect = 0.0f64;
    loop {
        h.step();
        if done(h.state()) {
            return true;
        }
        if let Some(r) = &h.state().running {
            expect = expect.max(r.total);
        }
        if start.elapsed().as_secs_f64() > srv.wall(2.0 * expect, extra) {
            return false;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}

/// Types `text` into the parameter field `path` and presses Enter (a set).
pub fn type_param(
    h: &mut egui_kittest::Harness<'static, gms_tune::ui::App>,
    path: &str,
    text: &str,
) {
    replace_text(h, path, text);
    h.key_press(egui::Key::Enter);
    h.step();
}

/// Replaces the text of the field labelled `label` with `text`.
pub fn replace_text(
    h: &mut egui_kittest::Harness<'static, gms_tune::ui::App>,
    label: &str,
    text: &str,
) {
    use egui_kittest::kittest::Queryable;
    h.get_by_label(label).click();
    h.step();
    h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::A);
    h.step();
    h.get_by_label(label).type_text(text);
    h.step();
}
