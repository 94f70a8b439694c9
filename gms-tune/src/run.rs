//! The link as a bench for long runs (identify, commission, tune-ff), shared by the command
//! line and the window: a stop flag (Ctrl-C, or the window's Stop) that ends the run at its
//! next request or wait while the requests that end a run safely still go out, and hooks told
//! of each stage and each wait (a progress bar, or the window's progress and telemetry).

use gms_core::protocol::Command;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use gms_bench::DeviceLink;
use gms_bench::frf::{MIN_COHERENCE, Suggestion, Sweep};
use gms_core::device::{StatusReply, StatusValue};

use crate::Link;

/// What a run reports as it goes.
pub trait Hooks {
    /// A stage starts (`what`), expected to take `seconds` of device time.
    fn stage(&mut self, what: &str, seconds: f64);
    /// `seconds` of device time were waited.
    fn waited(&mut self, seconds: f64);
}

/// The link as a stoppable bench.
pub struct RunBench<'a, 'h> {
    /// The link.
    pub link: &'a mut Link,
    stop: Arc<AtomicBool>,
    why: &'static str,
    hooks: &'h mut dyn Hooks,
}

impl<'a, 'h> RunBench<'a, 'h> {
    /// The link; `stop` set ends the run (`why` says by what, e.g. "interrupted (Ctrl-C)").
    pub fn new(
        link: &'a mut Link,
        stop: Arc<AtomicBool>,
        why: &'static str,
        hooks: &'h mut dyn Hooks,
    ) -> RunBench<'a, 'h> {
        RunBench {
            link,
            stop,
            why,
            hooks,
        }
    }

    fn stopped(&self) -> Result<(), gms_link::Error> {
        if self.stop.load(Ordering::SeqCst) {
            Err(gms_link::Error::Lost(self.why.into()))
        } else {
            Ok(())
        }
    }

    /// A stage starts.
    pub fn stage(&mut self, what: &str, seconds: f64) {
        self.hooks.stage(what, seconds);
    }
}

impl DeviceLink for RunBench<'_, '_> {
    fn request(&mut self, c: Command<'_>) -> Result<(Vec<String>, String), gms_link::Error> {
        self.stopped()?;
        DeviceLink::request(&mut *self.link, c)
    }

    fn request_to_end(&mut self, c: Command<'_>) -> Result<(Vec<String>, String), gms_link::Error> {
        DeviceLink::request(&mut *self.link, c)
    }

    /// Waits in device time, the progress told as it passes and the stop flag looked at
    /// between looks at the device's clock (a Stop ends a long wait within 50 ms, whatever
    /// the device's pace).
    fn pass(&mut self, seconds: f64) -> Result<(), gms_link::Error> {
        self.stopped()?;
        let (stop, hooks) = (&self.stop, &mut *self.hooks);
        self.link
            .wait_device_with(seconds, &mut |passed| {
                hooks.waited(passed);
                !stop.load(Ordering::SeqCst)
            })
            .map_err(crate::LinkError::into_link)?;
        self.stopped()
    }
}

/// The parameter file of an identification and its text (the report lines as comments, the
/// data's directory named), as `gms-tune identify` and the window write it.
pub fn identified_file(
    id: &gms_ident::identify::Identified,
    report: &std::path::Path,
) -> (gms_ident::paramfile::ParamFile, String) {
    let file = gms_ident::paramfile::ParamFile {
        friction: id.spec.clone(),
        device: None,
    };
    let text = format!(
        "# identified by gms-tune identify (data in {})\n{}{}",
        report.display(),
        id.report
            .iter()
            .map(|l| format!("# {l}\n"))
            .collect::<String>(),
        file.to_toml()
    );
    (file, text)
}

/// An identification's results written as `gms-tune identify` writes them: the report and
/// its plots in `report`, and (with `out`) the parameter file of [`identified_file`]; returns
/// the file and its text.
pub fn write_identified(
    id: &gms_ident::identify::Identified,
    report: &std::path::Path,
    out: Option<&std::path::Path>,
) -> Result<(gms_ident::paramfile::ParamFile, String), gms_bench::Error> {
    gms_ident::identify::write_report(id, report)?;
    let (file, text) = identified_file(id, report);
    if let Some(out) = out {
        gms_ident::io::write_atomic(out, text.as_bytes())?;
    }
    Ok((file, text))
}

/// The parameter file of a commissioning — the device's parameters `pf` with the settings
/// found in `[device]` — and its text (the steps' lines as comments), as `gms-tune commission`
/// and the window write it.
pub fn commissioned_file(
    c: &gms_bench::Commissioned,
    mut pf: gms_ident::paramfile::ParamFile,
) -> (gms_ident::paramfile::ParamFile, String) {
    let mut device = toml::Table::new();
    for (k, v) in c.settings() {
        device.insert(k.to_string(), toml::Value::Float(v));
    }
    pf.device = Some(device);
    let text = format!(
        "# commissioned by gms-tune commission\n{}{}",
        c.lines
            .iter()
            .map(|l| format!("# {l}\n"))
            .collect::<String>(),
        pf.to_toml()
    );
    (pf, text)
}

/// A step test's samples `(t, ref, pos, error, ff, friction)` (SI) as a trace, and its figures
/// by `gms_ident::trace::metrics` for the one move of `distance` \[rad\] the device made with
/// its default profile (`move POS`), dwelling `seconds` after it, on an encoder of
/// `rad_per_count` \[rad\]: what `gms-tune step-test` and the window both report.
pub fn step_figures(
    rows: &[[f64; 6]],
    distance: f64,
    seconds: f64,
    rad_per_count: f64,
) -> (Vec<gms_ident::trace::TraceRow>, gms_ident::trace::Metrics) {
    use gms_core::control::reference::{MOVE_AMAX, MOVE_JMAX, MOVE_VMAX};
    let trace: Vec<gms_ident::trace::TraceRow> = rows
        .iter()
        .map(|r| gms_ident::trace::TraceRow {
            t: r[0],
            reference: r[1],
            position: r[2],
            error: r[3],
            current: 0.0,
            current_cmd: 0.0,
            voltage: 0.0,
            friction: r[5],
            feedforward: r[4],
            ff_scale: 1.0,
            drift: 1.0,
            ref_velocity: 0.0,
            segment: 0,
        })
        .collect();
    let seg = gms_core::control::reference::Segment::Move {
        distance: distance as f32,
        vmax: MOVE_VMAX,
        amax: MOVE_AMAX,
        jmax: MOVE_JMAX,
        dwell: seconds as f32,
    };
    let m = gms_ident::trace::metrics(&trace, &[seg], rad_per_count);
    (trace, m)
}

/// The fields a step test records, in [`step_figures`]' order.
pub const STEP_FIELDS: &str = "t,ref,pos,error,ff,friction";

/// `gms-tune step-test`: the bridge on, the position read, the stream of [`STEP_FIELDS`] at
/// 1 kHz, a `move` by `distance` \[rad\] with the device's default profile, `seconds` of
/// recording; the rows, the trace, its figures ([`step_figures`]) and the device's encoder
/// resolution \[rad/count\].
#[allow(clippy::type_complexity)]
pub fn step_test(
    link: &mut Link,
    distance: f64,
    seconds: f64,
) -> Result<
    (
        Vec<[f64; 6]>,
        Vec<gms_ident::trace::TraceRow>,
        gms_ident::trace::Metrics,
        f64,
    ),
    crate::LinkError,
> {
    let rpc = gms_bench::rad_per_count(link).map_err(crate::LinkError::Bench)?;
    link.ask(Command::Enable { current: false })?;
    let pos0 = link
        .record("pos", 100.0, 0.05)?
        .last()
        .and_then(|r| r.first().copied())
        .unwrap_or(0.0);
    link.telemetry.clear();
    link.ask(Command::Stream {
        fields: STEP_FIELDS,
        rate_hz: 1000.0,
    })?;
    link.ask(Command::Move {
        pos: (pos0 + distance) as f32,
        vel: None,
    })?;
    let listened = link.listen(std::time::Duration::from_secs_f64(seconds));
    let off = link.ask(Command::StreamOff);
    listened?;
    off?;
    let six: Vec<[f64; 6]> = link
        .telemetry_rows(STEP_FIELDS)
        .iter()
        .map(|r| [r[0], r[1], r[2], r[3], r[4], r[5]])
        .collect();
    let (trace, m) = step_figures(&six, distance, seconds, rpc);
    Ok((six, trace, m, rpc))
}

/// `tune-ff`'s result as summary lines, for the terminal (gains to 3 decimals, errors in counts).
pub fn tune_ff_summary(t: &gms_bench::TuneFf) -> Vec<String> {
    let mut out = Vec::new();
    for n in &t.notes {
        out.push(format!("note: {n}"));
    }
    match t.optimum {
        Some(o) if t.decided => out.push(format!(
            "ff.gain {:.3} ± {:.3} (95 %; a repeat of this tuning lands within ±{:.3}), \
             RMS error there {:.2} counts; was {:.3}",
            o.at,
            o.half_width(),
            o.repeat_half_width(),
            o.min.max(0.0).sqrt() / t.rad_per_count,
            t.before
        )),
        Some(o) => out.push(format!(
            "no clear optimum: the fit says {:.3} ± {:.3}; ff.gain stays {:.3}",
            o.at,
            o.half_width(),
            t.before
        )),
        None => out.push(format!("no optimum found; ff.gain stays {:.3}", t.before)),
    }
    out
}

/// `tune-ff`'s result as JSON: raw values in SI (gains, RMS errors in rad).
pub fn tune_ff_json(t: &gms_bench::TuneFf) -> serde_json::Value {
    serde_json::json!({
        "before": t.before,
        "chosen": t.chosen,
        "decided": t.decided,
        "optimum": t.optimum.map(|o| o.at),
        "standard_error": t.optimum.map(|o| o.se),
        "half_width_95": t.optimum.map(|o| o.half_width()),
        "rms_at_optimum_rad": t.optimum.map(|o| o.min.max(0.0).sqrt()),
        "range": [t.range.0, t.range.1],
        "window": [t.window.0, t.window.1],
        "notes": t.notes,
        "curve": t.curve.iter().map(|(g, r)| serde_json::json!({"gain": g, "rms_rad": r})).collect::<Vec<_>>(),
    })
}

/// What a status key means and its unit, for the table.
fn status_meaning(key: &str) -> (&'static str, &'static str) {
    match key {
        "mode" => ("feedforward mode", ""),
        "enabled" => ("bridge on (1) or off (0)", ""),
        "faults" => ("latched faults, bit mask", ""),
        "fault_names" => ("latched faults", ""),
        "t" => ("device time", "s"),
        "pos" => ("position from power-up", "rad"),
        "error_counts" => ("position error", "counts"),
        "moving" => ("a move under way", ""),
        "current" => ("measured current", "A"),
        "ff" => ("friction feedforward (estimate of the friction)", "N·m"),
        "duty" => ("PWM duty", ""),
        "step_us_worst" => ("longest control step", "µs"),
        "step_us_mean" => ("mean control step", "µs"),
        "sense_offset" => ("current-sense zero", "ADC codes"),
        "missed" => ("control periods missed", ""),
        "late" => ("control steps that wrote their duty late", ""),
        "duty_max" => ("largest duty the current sense allows", ""),
        "duty_limited" => ("current steps held at duty_max", ""),
        "supply" => ("motor supply (measured where the board has a divider)", "V"),
        "drive" => ("what the loop drives", ""),
        "configured" => (
            "settings chosen for this axis (1) or built-in defaults (0)",
            "",
        ),
        _ => ("", ""),
    }
}

/// A status value as text: whole numbers as they are, others to four significant digits.
fn status_text(v: StatusValue) -> String {
    match v {
        StatusValue::Number(x) if x.fract() == 0.0 && x.abs() < 1e15 => format!("{x}"),
        StatusValue::Number(x) => gms_ident::units::num4(x),
        StatusValue::Text(t) => t.to_string(),
        StatusValue::Faults(f) => gms_bench::fault_names(f),
    }
}

/// The status as aligned lines: key, value (numbers to a sensible precision, with the unit),
/// and what it means.
pub fn status_table(st: &StatusReply) -> Vec<String> {
    let entries = st.entries();
    let width = entries.iter().map(|(k, _)| k.len()).max().unwrap_or(0);
    entries
        .iter()
        .map(|&(k, v)| {
            let (meaning, unit) = status_meaning(k);
            let value = format!("{} {unit}", status_text(v));
            format!("{k:<width$}  {:<22}  {meaning}", value.trim_end())
                .trim_end()
                .to_string()
        })
        .collect()
}

/// The status as one JSON object: numbers as numbers, names as strings.
pub fn status_json(st: &StatusReply) -> serde_json::Value {
    let map: serde_json::Map<String, serde_json::Value> = st
        .entries()
        .iter()
        .map(|&(k, v)| {
            let val = match v {
                StatusValue::Number(x) => serde_json::Number::from_f64(x)
                    .map_or(serde_json::Value::Null, serde_json::Value::Number),
                other => serde_json::Value::String(status_text(other)),
            };
            (k.to_string(), val)
        })
        .collect();
    serde_json::Value::Object(map)
}

/// A step test's figures as readable lines: the step in mrad and counts, the settle time and
/// its band, the steady-state error, the largest error, hunting (no sine or reversal figures:
/// they do not apply to a step).
pub fn step_summary(
    m: &gms_ident::trace::Metrics,
    distance: f64,
    trace: &[gms_ident::trace::TraceRow],
    rad_per_count: f64,
) -> Vec<String> {
    let c = rad_per_count;
    let span = match (trace.first(), trace.last()) {
        (Some(a), Some(b)) => b.t - a.t,
        _ => 0.0,
    };
    let mut out = vec![format!(
        "step {:.3} mrad ({:.0} counts), {} samples over {:.2} s",
        distance * 1e3,
        distance / c,
        trace.len(),
        span
    )];
    let band = format!(
        "band ±{:.1} counts: 1 count + 2 standard deviations of the error at rest, \
         excursions under {:.0} ms ignored",
        m.settle_band / c,
        gms_ident::trace::SPIKE * 1e3
    );
    if m.unsettled_steps > 0.0 {
        out.push(format!(
            "settle time        not settled within the record ({band})"
        ));
    } else {
        out.push(format!(
            "settle time        {:.1} ms after the reference stopped ({band})",
            m.settle_time * 1e3
        ));
    }
    out.push(format!(
        "steady-state error {:.2} counts (mean |error| over the last 20 % of the record)",
        m.steady_state_error / c
    ));
    out.push(format!(
        "largest error      {:.1} counts (during the move: the following error)",
        m.max_error / c
    ));
    out.push(if m.hunting_crossings > 0.0 {
        format!(
            "hunting            yes: a sustained oscillation about the target, {:.0} crossings \
             (a limit cycle)",
            m.hunting_crossings
        )
    } else {
        "hunting            none (the error dithers: within 1 count RMS, or not periodic)"
            .to_string()
    });
    out
}

/// `gms-tune frf`'s readable result: the points above the noise, the margins (and a
/// warning under `gms_bench::commission::MIN_PHASE_MARGIN` or `MIN_GAIN_MARGIN`), the pre-sliding stiffness
/// beside the device's model, the notch proposed and the margins it would give.
pub fn frf_summary(s: &Sweep, sug: Option<&Suggestion>) -> Vec<String> {
    let mut out = Vec::new();
    let good = s
        .points
        .iter()
        .filter(|p| p.coherence >= MIN_COHERENCE)
        .count();
    out.push(format!(
        "{good} of {} points above the noise (coherence ≥ {MIN_COHERENCE})",
        s.points.len()
    ));
    if let Some(m) = &s.margins {
        out.push(format!(
            "crossover {:.1} Hz; phase margin {:.1}° (at {:.0} Hz); gain margin {:.2} dB (at {:.0} Hz); peak sensitivity {:.2} dB (at {:.0} Hz)",
            m.crossover_hz,
            m.phase_margin_deg,
            m.phase_margin_hz,
            m.gain_margin_db,
            m.gain_margin_hz,
            m.peak_sensitivity_db,
            m.peak_sensitivity_hz
        ));
        let (pm, gm) = (
            gms_bench::commission::MIN_PHASE_MARGIN,
            gms_bench::commission::MIN_GAIN_MARGIN,
        );
        if m.phase_margin_deg < pm || m.gain_margin_db < gm {
            out.push(format!(
                "warning: the margins {:.1}° and {:.2} dB are under the floor of {pm}° and \
                 {gm} dB (what commissioning leaves): the loop rings, or goes unstable with a \
                 little more gain (--suggest proposes a notch; or lower pos.kp/pos.kd)",
                m.phase_margin_deg, m.gain_margin_db
            ));
        }
    }
    if let Some((k, j)) = s.presliding {
        out.push(format!(
            "pre-sliding stiffness {k:.4} N·m/rad (inertia {j:.3e} kg·m²); the device's GMS \
             model: Σk = {:.4} N·m/rad ({:+.1} %). At this amplitude; a larger one slips the \
             stiffest blocks and reads softer.",
            s.model_stiffness,
            100.0 * (k / s.model_stiffness - 1.0)
        ));
    }
    if let Some(g) = sug {
        out.push(format!(
            "resonance at {:.1} Hz ({:+.1} dB): notch {} at {:.1} Hz, q {}, {} dB deep",
            g.resonance.0,
            g.resonance.1,
            g.slot + 1,
            g.notch.f_hz,
            g.notch.q,
            g.notch.depth_db
        ));
        out.push(format!(
            "with it: phase margin {:.1}° (was {:.1}°), gain margin {:.2} dB (was {:.2} dB), \
             peak sensitivity {:.2} dB (was {:.2} dB)",
            g.after.phase_margin_deg,
            g.before.phase_margin_deg,
            g.after.gain_margin_db,
            g.before.gain_margin_db,
            g.after.peak_sensitivity_db,
            g.before.peak_sensitivity_db
        ));
        if s.plan.velocity.is_none() {
            out.push(
                "  (measured at rest: a resonance of the friction's pre-sliding spring moves with \
                 the amplitude and is gone when the axis slides, and a notch near the sliding \
                 loop's crossover costs it phase; --velocity shows the stage's own resonances)"
                    .into(),
            );
        }
    }
    out
}

fn json_num(x: f64) -> serde_json::Value {
    serde_json::Number::from_f64(x).map_or(serde_json::Value::Null, serde_json::Value::Number)
}

fn margins_json(m: &gms_bench::frf::Margins) -> serde_json::Value {
    serde_json::json!({
        "gain_margin_db": json_num(m.gain_margin_db),
        "gain_margin_hz": json_num(m.gain_margin_hz),
        "phase_margin_deg": json_num(m.phase_margin_deg),
        "phase_margin_hz": json_num(m.phase_margin_hz),
        "crossover_hz": json_num(m.crossover_hz),
        "peak_sensitivity_db": json_num(m.peak_sensitivity_db),
        "peak_sensitivity_hz": json_num(m.peak_sensitivity_hz),
    })
}

/// `gms-tune frf --json`: the points, the margins, the pre-sliding fit, the notch proposed
/// (non-finite values as null).
pub fn frf_json(s: &Sweep, sug: Option<&Suggestion>) -> serde_json::Value {
    serde_json::json!({
        "loop": s.plan.lp.name(),
        "points": s.points.iter().map(|p| serde_json::json!({
            "f_hz": json_num(p.f_hz),
            "gain_db": json_num(p.gain_db()),
            "phase_deg": json_num(p.phase_deg()),
            "coherence": json_num(p.coherence),
        })).collect::<Vec<_>>(),
        "margins": s.margins.as_ref().map(margins_json),
        "presliding": s.presliding.map(|(k, j)| serde_json::json!({
            "stiffness": json_num(k), "inertia": json_num(j), "model_stiffness": json_num(s.model_stiffness),
        })),
        "suggestion": sug.map(|g| serde_json::json!({
            "slot": g.slot + 1,
            "f_hz": json_num(g.notch.f_hz as f64),
            "q": json_num(g.notch.q as f64),
            "depth_db": json_num(g.notch.depth_db as f64),
            "before": margins_json(&g.before),
            "after": margins_json(&g.after),
        })),
    })
}
