//! `gms-tune commission`: `gms_bench::commission` on the link, its lines and summary,
//! the parameter file, and — only after every step succeeded — the settings loaded and saved.

use gms_core::protocol::Command;
use std::path::Path;

use gms_bench::Error;
use gms_bench::load_params;
use gms_tune::Link;

use crate::Fail;
use crate::tracked::{Bar, ctrl_c};
use gms_tune::jobs;

/// Runs the commissioning; writes `out`; applies/saves on request.
pub fn run(
    link: &mut Link,
    out: &Path,
    speed: f64,
    apply: bool,
    save: bool,
    force: bool,
    json: bool,
) -> Result<(), Fail> {
    let mut bar = Bar::new();
    let mut ctl = jobs::Control {
        stop: ctrl_c(),
        why: "interrupted (Ctrl-C)",
        hooks: &mut bar,
    };
    let r = jobs::commission(link, speed, Some(out), &mut ctl);
    let (c, pf) = match r {
        Ok(j) => (j.commissioned, j.file),
        Err(Error::Params(m)) => return Err(Fail::Usage(m)),
        Err(Error::Io(m)) => return Err(Fail::Usage(m)),
        Err(e) => {
            return Err(Fail::Device(format!(
                "{e}; the bridge is off, nothing changed"
            )));
        }
    };
    if json {
        let settings: serde_json::Map<String, serde_json::Value> = c
            .settings()
            .into_iter()
            .map(|(k, v)| (k.to_string(), serde_json::json!(v)))
            .collect();
        let v = serde_json::json!({
            "settings": settings,
            "inductance_h": c.inductance,
            "sense_offset_a": c.sense_offset,
            "sense_noise_a": c.sense_noise,
            "lines": c.lines,
            "short_of_floor": c.short_of_floor,
            "file": out.display().to_string(),
        });
        println!("{v}");
    } else {
        for l in &c.lines {
            println!("{l}");
        }
        use gms_ident::units::{num4, si};
        println!(
            "summary: sense.dir {}, enc.dir {}, motor.r {}, motor.k_e = motor.k_m {} V·s/rad \
             ({}); wrote {}",
            c.sense_dir,
            c.enc_dir,
            si(c.r, "Ω"),
            num4(c.k_e),
            si(c.k_e, "V·s/rad"),
            out.display()
        );
    }
    if let (true, false, Some(why)) = (apply || save, force, &c.short_of_floor) {
        return Err(Fail::Device(format!(
            "{why}: not applied (--force applies it anyway; {} holds it); the device is as it \
             was",
            out.display()
        )));
    }
    if apply || save {
        let n = load_params(link, &pf).map_err(|e| Fail::Device(e.to_string()))?;
        eprintln!("loaded into the device ({n} parameters changed)");
        if save {
            link.ask(Command::Save)?;
            eprintln!("saved");
        }
    }
    Ok(())
}
