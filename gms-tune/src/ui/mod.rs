//! `gms-tune ui`: the bench tool's window (eframe/egui, egui_plot): live plots of the
//! device's telemetry, the friction loop, the parameter tree, the device's controls. The link
//! runs on a worker thread ([`worker`]); the window ([`app`]) only shows and sends.

pub mod app;
pub mod worker;

use std::path::PathBuf;
use std::time::{Duration, Instant};

pub use app::App;
pub use worker::Endpoint;

/// A screenshot to take: the file (PNG) and the wall time after opening \[s\]; the window
/// closes after it.
#[derive(Debug, Clone)]
pub struct Screenshot {
    /// The PNG file.
    pub path: PathBuf,
    /// When \[s\] after the window opens.
    pub after: f64,
}

/// The eframe application around [`App`].
struct Window {
    app: App,
    opened: Instant,
    screenshot: Option<Screenshot>,
    /// Frames drawn since the window opened.
    frames: u64,
}

impl eframe::App for Window {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        self.app.show(ui);
        self.frames += 1;
        if let Some(s) = &self.screenshot
            && self.opened.elapsed().as_secs_f64() >= s.after
        {
            let path = s.path.clone();
            self.screenshot = None;
            let secs = self.opened.elapsed().as_secs_f64();
            eprintln!(
                "{} frames in {secs:.1} s ({:.1} frames/s), {} samples received",
                self.frames,
                self.frames as f64 / secs,
                self.app.received
            );
            let ctx = ui.ctx().clone();
            ui.ctx().request_screenshot(move |img| {
                let [w, h] = img.size;
                let bytes: Vec<u8> = img.pixels.iter().flat_map(|c| c.to_array()).collect();
                match image::RgbaImage::from_raw(w as u32, h as u32, bytes)
                    .ok_or_else(|| "bad image size".to_string())
                    .and_then(|i| i.save(&path).map_err(|e| e.to_string()))
                {
                    Ok(()) => eprintln!("screenshot written to {}", path.display()),
                    Err(e) => eprintln!("error: {}: {e}", path.display()),
                }
                ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            });
        }
    }
}

/// Opens the window on `endpoint` (reply timeout `timeout`; `first`: request lines sent once
/// the link is up; `tab`: the page shown first) and runs it until closed.
pub fn run(
    endpoint: Endpoint,
    timeout: Duration,
    first: Vec<String>,
    tab: app::Tab,
    screenshot: Option<Screenshot>,
) -> Result<(), String> {
    let options = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_title(format!("gms-tune — {endpoint}"))
            .with_inner_size([1400.0, 900.0]),
        ..Default::default()
    };
    eframe::run_native(
        "gms-tune",
        options,
        Box::new(move |cc| {
            let mut app = App::new(endpoint, timeout, first, &cc.egui_ctx);
            app.tab = tab;
            Ok(Box::new(Window {
                app,
                opened: Instant::now(),
                screenshot,
                frames: 0,
            }))
        }),
    )
    .map_err(|e| format!("cannot open the window: {e}"))
}
