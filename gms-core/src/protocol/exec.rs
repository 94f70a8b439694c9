//! Executing a request against a device and writing its reply.

use super::*;

/// What the device does for the commands that are not about parameters. Every command can
/// be refused with a reason (the reply is then `err 8 <reason>` and nothing changed).
pub trait Device {
    /// A new host's session starts ([`Line::Cancel`]): the previous host's stream and
    /// experiment end, as when its link is seen gone. Nothing by default.
    fn new_session(&mut self) {}
    /// The current settings.
    fn settings(&self) -> &Settings;
    /// The set being staged by `stage` (the current settings with the staged changes), if
    /// any.
    fn staged(&mut self) -> &mut Option<Settings>;
    /// Applies a validated set (between two control steps); refused when the device cannot
    /// run it, and then nothing changes.
    fn apply(&mut self, new: Settings) -> Result<(), &'static str>;
    /// `lim.v_supply` was set by the host (a `set` of it, even to the value it had): on a
    /// board that does not measure its supply, that confirms it. Nothing by default.
    fn supply_confirmed(&mut self) {}
    /// Persists the current set.
    fn save(&mut self) -> Result<(), &'static str>;
    /// Restores the persisted set.
    fn load(&mut self) -> Result<(), &'static str>;
    /// Restores the built-in defaults.
    fn defaults(&mut self) -> Result<(), &'static str>;
    /// Switches the bridge on (position control).
    fn enable(&mut self) -> Result<(), &'static str>;
    /// Switches the bridge on straight into current mode at 0 A (no position control).
    fn enable_current(&mut self) -> Result<(), &'static str>;
    /// Switches the bridge off.
    fn disable(&mut self) -> Result<(), &'static str>;
    /// The device's state (`status`).
    fn status(&mut self) -> StatusReply;
    /// Clears latched faults.
    fn clear(&mut self) -> Result<(), &'static str>;
    /// Moves to `pos` \[rad\] at up to `vel` [rad/s].
    fn move_to(&mut self, pos: f32, vel: Option<f32>) -> Result<(), &'static str>;
    /// Holds the current `amps` \[A\] with the position loop off.
    fn current(&mut self, amps: f32, seconds: Option<f32>) -> Result<(), &'static str>;
    /// Runs at the speed `vel` [rad/s], with a `sweep` around it.
    fn velocity(
        &mut self,
        vel: f32,
        sweep: Option<crate::control::reference::Sweep>,
    ) -> Result<(), &'static str>;
    /// Back to position control: from a speed, stopping as the acceleration limit allows;
    /// from current mode, holding where the axis is.
    fn hold(&mut self) -> Result<(), &'static str>;
    /// Arms a capture of `fields` (comma-separated names) every `every` position steps,
    /// `samples` of them, from now or (`on_next`) from the next experiment request.
    fn capture_arm(
        &mut self,
        fields: &str,
        every: u32,
        samples: u32,
        on_next: bool,
    ) -> Result<(), &'static str>;
    /// Stops the capture and drops its data.
    fn capture_off(&mut self) -> Result<(), &'static str>;
    /// The capture's state (`capture`).
    fn capture_status(&mut self) -> CaptureStatus;
    /// Writes samples `start`.. (`count` at most) of the capture, one line each, values
    /// comma-separated in SI units.
    fn capture_read(
        &mut self,
        start: u32,
        count: u32,
        out: &mut dyn Write,
    ) -> Result<(), &'static str>;
    /// Starts telemetry of `fields` at `rate_hz`.
    fn stream(&mut self, fields: &str, rate_hz: f32) -> Result<(), &'static str>;
    /// Stops telemetry.
    fn stream_off(&mut self) -> Result<(), &'static str>;
    /// Starts a frequency-response measurement: a sine of `f_hz` \[Hz\] and `amp` (A or rad)
    /// injected at `injection`, `settle` periods let pass, `periods` summed.
    fn frf_start(
        &mut self,
        injection: crate::control::frf::Injection,
        f_hz: f32,
        amp: f32,
        periods: u32,
        settle: u32,
    ) -> Result<(), &'static str> {
        let _ = (injection, f_hz, amp, periods, settle);
        Err("no frequency response on this device")
    }
    /// Stops the frequency-response measurement under way.
    fn frf_off(&mut self) -> Result<(), &'static str> {
        Err("no frequency response on this device")
    }
    /// The frequency-response measurement's state and result (`frf`).
    fn frf_status(&mut self) -> FrfStatus {
        FrfStatus {
            state: crate::control::frf::FrfState::Idle,
            measure: None,
        }
    }
    /// Writes bins `start`.. of the position map from `pairs` (`offset,scale` separated by
    /// spaces): all or none.
    fn map_write(&mut self, start: u32, pairs: &str) -> Result<(), &'static str> {
        let _ = (start, pairs);
        Err("no position map on this device")
    }
    /// Writes bins `start`.. (`count` at most) of the position map, `offset,scale` a line.
    fn map_read(
        &mut self,
        start: u32,
        count: u32,
        out: &mut dyn Write,
    ) -> Result<(), &'static str> {
        let _ = (start, count, out);
        Err("no position map on this device")
    }
    /// Clears the position map (offsets 0, scales 1).
    fn map_clear(&mut self) -> Result<(), &'static str> {
        Err("no position map on this device")
    }
    /// The table motion's state (`table`; none on a device without one).
    fn table_status(&mut self) -> TableStatus {
        TableStatus(None)
    }
    /// Acts on a table motion's command (a read writes its values, one a line, to `out`).
    fn table(&mut self, cmd: TableCmd<'_>, out: &mut dyn Write) -> Result<(), &'static str> {
        let _ = (cmd, out);
        Err("no table motion on this device")
    }
    /// An on-line estimate (read-only parameter); 1 for the adaptive scale of a device
    /// without adaptation.
    fn estimate(&mut self, which: Estimate) -> f32 {
        match which {
            Estimate::AdaptScale => 1.0,
        }
    }
}

/// The `help` text.
pub const HELP: &str = "help | list | get PATH | set PATH VALUE | stage PATH VALUE | commit | \
discard | save | load | defaults | \
enable [current] | disable | status | clear | move POS [VEL] | current AMPS [SECONDS] | \
velocity VEL [AMP F0 F1 SECONDS] | hold | stream FIELDS RATE_HZ | stream off | \
capture [off | FIELDS EVERY SAMPLES [next] | read START COUNT] | \
frf [off | current|position F_HZ AMP PERIODS SETTLE] | \
map read START COUNT | map write START OFFSET,SCALE ... | map clear | \
table [ref|corr START V ... | corr off | set POINTS STEPS ORIGIN | use | run PERIODS | stop | \
read ref|corr|err START COUNT | clear]";

fn err(out: &mut impl Write, code: ErrorCode, reason: &str) -> fmt::Result {
    writeln!(out, "{}", Reply::Err(code, reason))
}

fn done(out: &mut impl Write, r: Result<(), &'static str>) -> fmt::Result {
    match r {
        Ok(()) => writeln!(out, "{}", Reply::Ok("")),
        Err(reason) => err(out, ErrorCode::Refused, reason),
    }
}

/// Handles one received line: parses it, acts on `dev`, writes the reply to `out`.
pub fn execute<D: Device, W: Write>(dev: &mut D, line: Line<'_>, out: &mut W) -> fmt::Result {
    let text = match line {
        Line::Text(t) => t,
        Line::TooLong => return err(out, ErrorCode::LineTooLong, "line too long"),
        Line::NotText => return err(out, ErrorCode::NotText, "not printable ASCII"),
        Line::Damaged => {
            return err(
                out,
                ErrorCode::LinkError,
                "line damaged on the link: not run (send it again)",
            );
        }
        Line::Cancel => {
            dev.new_session();
            return Ok(());
        }
    };
    let cmd = match parse(text) {
        Ok(c) => c,
        Err(e) => return err(out, e.code, e.reason),
    };
    match cmd {
        Command::Empty => Ok(()),
        Command::Help => {
            writeln!(out, "{HELP}")?;
            writeln!(out, "ok")
        }
        Command::List => {
            let s = *dev.settings();
            for p in PARAMS {
                let (value, range) = match p.access {
                    Access::Number { get, min, max, .. } => {
                        (ListValue::Number(get(&s)), ListRange::Number { min, max })
                    }
                    Access::Mode => (
                        ListValue::Name(s.ff.mode.name()),
                        ListRange::Names(MODE_NAMES),
                    ),
                    Access::Estimate(e) => {
                        (ListValue::Number(dev.estimate(e)), ListRange::ReadOnly)
                    }
                };
                ListRow {
                    path: p.path,
                    value,
                    unit: p.unit,
                    range,
                }
                .write(out)?;
            }
            writeln!(out, "ok")
        }
        Command::Get(path) => match find(path) {
            Some(p) => {
                out.write_str("ok ")?;
                write_param(p, dev, out)?;
                writeln!(out)
            }
            None => err(out, ErrorCode::UnknownPath, "unknown parameter (try list)"),
        },
        Command::Set(path, value) => match with_value(dev.settings(), path, value) {
            Ok(new) => {
                // A set made beside a staging would be undone by its commit: drop it.
                *dev.staged() = None;
                let r = dev.apply(new);
                if r.is_ok() && path == crate::settings::ParamId::LimVSupply.path() {
                    dev.supply_confirmed();
                }
                done(out, r)
            }
            Err(e) => err(out, e.code, e.reason),
        },
        Command::Stage(path, value) => {
            let base = dev.staged().unwrap_or(*dev.settings());
            match with_value_staged(&base, path, value) {
                Ok(new) => {
                    *dev.staged() = Some(new);
                    writeln!(out, "ok")
                }
                Err(e) => err(out, e.code, e.reason),
            }
        }
        Command::Commit => match dev.staged().take() {
            None => err(out, ErrorCode::Refused, "nothing staged"),
            Some(new) => match new.validate() {
                Ok(()) => done(out, dev.apply(new)),
                Err(_) => err(
                    out,
                    ErrorCode::InvalidSet,
                    "the staged set would be invalid (dropped, nothing changed)",
                ),
            },
        },
        Command::Discard => {
            *dev.staged() = None;
            writeln!(out, "ok")
        }
        Command::Save => done(out, dev.save()),
        Command::Load => {
            *dev.staged() = None;
            done(out, dev.load())
        }
        Command::Defaults => {
            *dev.staged() = None;
            done(out, dev.defaults())
        }
        Command::Enable { current: false } => done(out, dev.enable()),
        Command::Enable { current: true } => done(out, dev.enable_current()),
        Command::Disable => done(out, dev.disable()),
        Command::Status => {
            let st = dev.status();
            out.write_str("ok ")?;
            st.write(out)?;
            writeln!(out)
        }
        Command::Clear => done(out, dev.clear()),
        Command::Move { pos, vel } => done(out, dev.move_to(pos, vel)),
        Command::Current { amps, seconds } => done(out, dev.current(amps, seconds)),
        Command::Velocity { vel, sweep } => done(out, dev.velocity(vel, sweep)),
        Command::Hold => done(out, dev.hold()),
        Command::Capture(c) => match c {
            CaptureCmd::Status => {
                let st = dev.capture_status();
                out.write_str("ok ")?;
                st.write(out)?;
                writeln!(out)
            }
            CaptureCmd::Off => done(out, dev.capture_off()),
            CaptureCmd::Arm {
                fields,
                every,
                samples,
                on_next,
            } => done(out, dev.capture_arm(fields, every, samples, on_next)),
            CaptureCmd::Read { start, count } => {
                let r = dev.capture_read(start, count, out);
                done(out, r)
            }
        },
        Command::Stream { fields, rate_hz } => done(out, dev.stream(fields, rate_hz)),
        Command::StreamOff => done(out, dev.stream_off()),
        Command::Map(MapCmd::Read { start, count }) => {
            let r = dev.map_read(start, count, out);
            done(out, r)
        }
        Command::Map(MapCmd::Write { start, pairs }) => done(out, dev.map_write(start, pairs)),
        Command::Map(MapCmd::Clear) => done(out, dev.map_clear()),
        Command::Table(TableCmd::Status) => {
            let st = dev.table_status();
            out.write_str("ok ")?;
            st.write(out)?;
            writeln!(out)
        }
        Command::Table(t) => {
            let r = dev.table(t, out);
            done(out, r)
        }
        Command::Frf(FrfCmd::Status) => {
            let st = dev.frf_status();
            out.write_str("ok ")?;
            st.write(out)?;
            writeln!(out)
        }
        Command::Frf(FrfCmd::Off) => done(out, dev.frf_off()),
        Command::Frf(FrfCmd::Start {
            injection,
            f_hz,
            amp,
            periods,
            settle,
        }) => done(out, dev.frf_start(injection, f_hz, amp, periods, settle)),
    }
}
