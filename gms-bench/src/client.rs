//! The device as a bench: anything that answers the bench protocol — a board over USB or
//! UART, the virtual device over TCP (`gms-tune`'s link), the device core in-process on the
//! simulated plant (`hil-sim`'s `LocalDevice`) — and the primitives every workflow uses:
//! parameters, `status`, the capture, moves, the bridge off on failure.

use crate::Error;
use gms_core::protocol::ParamId;
use gms_ident::units::si;
pub use gms_link::DeviceLink;

use gms_core::device::{CaptureState, StatusReply};
use gms_core::protocol::CaptureStatus;
use gms_core::protocol::{CaptureCmd, Command, ErrorCode};

/// A device speaking the bench protocol ([`DeviceLink`]), with the workflows' conveniences:
/// every link is one (a blanket implementation).
pub trait Bench: DeviceLink {
    /// [`DeviceLink::request`], its failure a bench [`Error`].
    fn send(&mut self, c: Command<'_>) -> Result<(Vec<String>, String), Error> {
        self.request(c).map_err(Error::from)
    }

    /// [`DeviceLink::pass`], its failure a bench [`Error`].
    fn wait(&mut self, seconds: f64) -> Result<(), Error> {
        self.pass(seconds).map_err(Error::from)
    }

    /// [`DeviceLink::request_to_end`], its failure a bench [`Error`].
    fn send_to_end(&mut self, c: Command<'_>) -> Result<(Vec<String>, String), Error> {
        self.request_to_end(c).map_err(Error::from)
    }

    /// `set PATH VALUE` with a number (sent in f64's shortest decimal; the device rounds it
    /// to its f32).
    fn set(&mut self, param: ParamId, value: f64) -> Result<(), Error> {
        self.send(Command::Set(param.path(), &format!("{value}")))
            .map(drop)
    }

    /// `enable`: position control, holding where the axis is.
    fn enable(&mut self) -> Result<(), Error> {
        self.send(Command::Enable { current: false }).map(drop)
    }

    /// `disable`: the bridge off.
    fn disable(&mut self) -> Result<(), Error> {
        self.send(Command::Disable).map(drop)
    }

    /// `hold`: back to position control, stopping where the axis can.
    fn hold(&mut self) -> Result<(), Error> {
        self.send(Command::Hold).map(drop)
    }

    /// `clear`: the latched faults cleared.
    fn clear(&mut self) -> Result<(), Error> {
        self.send(Command::Clear).map(drop)
    }

    /// `current AMPS` \[A\]: the current held, the position loop off (until the next request).
    fn current(&mut self, amps: f64) -> Result<(), Error> {
        self.send(Command::Current {
            amps: amps as f32,
            seconds: None,
        })
        .map(drop)
    }

    /// `capture FIELDS EVERY SAMPLES [next]`: arms a capture of `fields` (comma-separated)
    /// every `every` position steps, `samples` of them, from now or (`on_next`) from the next
    /// experiment request.
    fn capture(
        &mut self,
        fields: &str,
        every: u32,
        samples: u32,
        on_next: bool,
    ) -> Result<(), Error> {
        self.send(Command::Capture(CaptureCmd::Arm {
            fields,
            every,
            samples,
            on_next,
        }))
        .map(drop)
    }
}

impl<T: DeviceLink + ?Sized> Bench for T {}

/// The capture's state ([`CaptureStatus::parse`]: the device core's own format).
pub fn capture_status(b: &mut impl Bench) -> Result<CaptureStatus, Error> {
    let (_, text) = b.send(Command::Capture(CaptureCmd::Status))?;
    CaptureStatus::parse(&text).map_err(|e| Error::Device(format!("{e}: {text}")))
}

/// The capture buffer's size the device reports (values: samples × fields at most that; the
/// board's, 8192 on the F405).
pub fn capture_capacity(b: &mut impl Bench) -> Result<u32, Error> {
    Ok(capture_status(b)?.capacity)
}

/// Every how many position steps `fields` fields are recorded so that `steps` steps fit in
/// `room` values (at least 1; 1 for a room of nothing, which the device then refuses).
pub fn decimation(steps: f64, fields: usize, room: f64) -> u32 {
    let every = (steps * fields as f64 / room).ceil();
    if every.is_finite() && every >= 1.0 {
        every.min(u32::MAX as f64) as u32
    } else {
        1
    }
}

/// Waits until the capture is `done`, letting `step` seconds of device time pass between
/// looks, at most `tries` looks.
pub fn capture_wait(b: &mut impl Bench, step: f64, tries: u32) -> Result<CaptureStatus, Error> {
    for _ in 0..tries {
        let st = capture_status(b)?;
        if st.state == CaptureState::Done {
            return Ok(st);
        }
        b.wait(step)?;
    }
    Err(Error::Device("the capture did not finish".into()))
}

/// Every sample of a finished capture, as rows of its fields (SI), read 64 at a time.
pub fn capture_rows(b: &mut impl Bench) -> Result<Vec<Vec<f64>>, Error> {
    let st = capture_status(b)?;
    if st.state != CaptureState::Done {
        return Err(Error::Device(format!(
            "no finished capture (state {})",
            st.state.name()
        )));
    }
    read_rows(b, st.samples, "capture", |start, count| {
        Command::Capture(CaptureCmd::Read { start, count })
    })
}

/// Reads `n` rows of comma-separated numbers that the device answers in chunks (capture, map
/// and table reads): `request(start, count)` the request line for rows `start`.. (at most
/// [`gms_core::protocol::MAX_READ`] a request); `what` names them in an error.
pub fn read_rows(
    b: &mut impl Bench,
    n: u32,
    what: &str,
    request: impl Fn(u32, u32) -> Command<'static>,
) -> Result<Vec<Vec<f64>>, Error> {
    let mut rows = Vec::with_capacity(n as usize);
    let mut start = 0;
    while start < n {
        let count = (n - start).min(gms_core::protocol::MAX_READ);
        let (lines, _) = b.send(request(start, count))?;
        if lines.is_empty() {
            return Err(Error::Device(format!("{what} read {start}: nothing read")));
        }
        for l in &lines {
            let row: Result<Vec<f64>, _> = gms_core::protocol::row(l).collect();
            rows.push(row.map_err(|_| Error::Device(format!("bad {what} line: {l}")))?);
        }
        start += lines.len() as u32;
    }
    Ok(rows)
}

/// Records `fields` every position step for `samples` steps from now and returns the rows.
pub fn capture_now(
    b: &mut impl Bench,
    fields: &str,
    samples: u32,
    step_s: f64,
) -> Result<Vec<Vec<f64>>, Error> {
    b.capture(fields, 1, samples, false)?;
    b.wait(samples as f64 * step_s)?;
    capture_wait(b, 0.01, 200)?;
    capture_rows(b)
}

/// A numeric parameter of the device (`get PATH`).
pub fn get_param(b: &mut impl Bench, param: ParamId) -> Result<f64, Error> {
    let (_, v) = b.send(Command::Get(param.path()))?;
    v.trim()
        .parse()
        .map_err(|_| Error::Device(format!("{param}: not a number: {v}")))
}

/// A numeric parameter of the device, `None` when the device does not know the path (a
/// firmware older than the parameter).
pub fn get_param_if_known(b: &mut impl Bench, param: ParamId) -> Result<Option<f64>, Error> {
    match get_param(b, param) {
        Ok(v) => Ok(Some(v)),
        Err(e) if e.refused_with(ErrorCode::UnknownPath) => Ok(None),
        Err(e) => Err(e),
    }
}

/// The encoder of a firmware older than `enc.counts_per_rev` \[rad/count\]: the paper's
/// 3.8 µrad, then a constant of the device.
pub const PAPER_RAD_PER_COUNT: f64 = 3.8e-6;

/// The device's encoder resolution \[rad/count\]: 2π / `enc.counts_per_rev`, for figures in
/// counts (the device's own, never an assumed encoder; [`PAPER_RAD_PER_COUNT`] on a firmware
/// that predates the parameter).
pub fn rad_per_count(b: &mut impl Bench) -> Result<f64, Error> {
    // A firmware from before the resolution was a parameter ran the paper's encoder.
    let Some(counts) = get_param_if_known(b, ParamId::EncCountsPerRev)? else {
        return Ok(PAPER_RAD_PER_COUNT);
    };
    if !(counts.is_finite() && counts > 0.0) {
        return Err(Error::Device(format!(
            "enc.counts_per_rev: {counts} is not a resolution"
        )));
    }
    Ok(std::f64::consts::TAU / counts)
}

/// The velocity mode's ramp [rad/s²] (the device's `velocity` ramps at `MOVE_AMAX`).
pub(crate) const VELOCITY_ACC: f64 = gms_core::control::reference::MOVE_AMAX as f64;

/// What the experiments need to know of the device, read with `get` (SI).
#[derive(Debug, Clone, Copy)]
pub struct DeviceInfo {
    /// Torque constant k_M [N·m/A].
    pub k_m: f64,
    /// Position-loop rate \\[Hz\\].
    pub pos_hz: f64,
    /// Current limit \\[A\\].
    pub i_max: f64,
    /// The compensator's static friction, the expected breakaway torque [N·m].
    pub fs: f64,
    /// The compensator's Stribeck velocity [rad/s].
    pub vs: f64,
    /// The encoder's resolution \\[rad/count\\].
    pub rad_per_count: f64,
}

impl DeviceInfo {
    /// Reads the parameters from the device.
    pub fn read(b: &mut impl Bench) -> Result<DeviceInfo, Error> {
        let info = DeviceInfo {
            k_m: get_param(b, ParamId::MotorKM)?,
            pos_hz: get_param(b, ParamId::RatePosHz)?,
            i_max: get_param(b, ParamId::LimIMax)?,
            fs: get_param(b, ParamId::GmsFs)?,
            vs: get_param(b, ParamId::GmsVs)?,
            rad_per_count: rad_per_count(b)?,
        };
        let ok = |v: f64| v.is_finite() && v > 0.0;
        if !(ok(info.k_m) && ok(info.pos_hz) && ok(info.i_max) && ok(info.fs) && ok(info.vs)) {
            return Err(Error::Device(format!(
                "the device's parameters cannot plan an experiment: {info:?}"
            )));
        }
        Ok(info)
    }

    /// One position step \\[s\\].
    pub fn dt(&self) -> f64 {
        1.0 / self.pos_hz
    }
}

/// The device's answer to a bench tool that is about to measure: an error when it runs on
/// its built-in defaults (its status says `configured=0`: the encoder's resolution and the
/// sense's scale are the paper's rig's, which no user's axis is), naming what to set.
pub fn check_configured(b: &mut impl Bench) -> Result<(), Error> {
    if !status(b)?.configured {
        return Err(Error::Device(
            "the device runs on its built-in defaults (never configured): set \
             enc.counts_per_rev and sense.v_per_a for this axis, then save (docs/bring-up.md)"
                .into(),
        ));
    }
    Ok(())
}

/// The device's encoder and current sense as one line for a report: counts per revolution,
/// radians per count, volts per ampere.
pub fn scales_line(b: &mut impl Bench) -> Result<String, Error> {
    let counts = get_param(b, ParamId::EncCountsPerRev)?;
    let rpc = rad_per_count(b)?;
    let v_per_a = get_param(b, ParamId::SenseVPerA)?;
    Ok(format!(
        "encoder: {counts} counts/rev ({}/count); current sense: {} V/A",
        si(rpc, "rad"),
        gms_ident::units::num4(v_per_a)
    ))
}

/// The device's `status`, read ([`StatusReply::parse`]: the device core's own format).
pub fn status(b: &mut impl Bench) -> Result<StatusReply, Error> {
    let (_, text) = b.send(Command::Status)?;
    StatusReply::parse(&text).map_err(|e| Error::Device(format!("{e}: {text}")))
}

/// The device's latched faults, as an error naming them ([`Error::Faulted`]), if any.
pub fn check_faults(b: &mut impl Bench) -> Result<(), Error> {
    let faults = status(b)?.faults;
    if faults.is_empty() {
        return Ok(());
    }
    Err(Error::Faulted {
        faults,
        during: None,
    })
}

/// Runs `f`; if it fails, switches the bridge off (best effort: the link may be gone) and
/// passes the error on.
pub fn guarded<B: Bench, T>(
    b: &mut B,
    f: impl FnOnce(&mut B) -> Result<T, Error>,
) -> Result<T, Error> {
    match f(b) {
        Ok(v) => Ok(v),
        Err(e) => {
            // A latched fault is the reason a later request failed: say which.
            let e = match (check_faults(b), e.faults()) {
                (Err(Error::Faulted { faults, .. }), None) => Error::Faulted {
                    faults,
                    during: Some(e.to_string()),
                },
                (_, _) => e,
            };
            let _ = b.send_to_end(Command::Disable);
            Err(e)
        }
    }
}

/// `velocity VEL [AMP F0 F1 SECONDS]` [rad/s, rad/s, Hz, Hz, s]: a constant speed, or a sweep
/// around it (`sweep`: amplitude, start and end frequency, duration).
pub fn velocity(vel: f64, sweep: Option<(f64, f64, f64, f64)>) -> Command<'static> {
    Command::Velocity {
        vel: vel as f32,
        sweep: sweep.map(
            |(amp, f0, f1, seconds)| gms_core::control::reference::Sweep {
                amp: amp as f32,
                f0: f0 as f32,
                f1: f1 as f32,
                seconds: seconds as f32,
            },
        ),
    }
}

/// A request of a bench primitive, with a clear error when the device does not know it (a
/// firmware older than the primitives).
pub(crate) fn primitive(b: &mut impl Bench, c: Command<'_>) -> Result<(), Error> {
    match b.send(c) {
        Ok(_) => Ok(()),
        // An older parser: the command unknown, or its new argument extra.
        Err(Error::Refused(e))
            if e.is(ErrorCode::UnknownCommand) || e.is(ErrorCode::BadArgument) =>
        {
            Err(Error::Device(format!(
                "the device does not know `{}` ({e}): its firmware predates the bench experiments; \
             update it",
                c.name()
            )))
        }
        Err(e) => Err(e),
    }
}

/// A timed velocity run from rest, captured whole (`fields`, beginning with `t`): `velocity V
/// 0 1 1 SECONDS` — no swing, then a ramp to rest the device makes by itself, so the stroke
/// never depends on the link's timing (a late stop over a slow link, or on a virtual device
/// faster than real time, would overrun the window). Waits for it and its ramps, checks the
/// faults, holds; the rows are then read with [`capture_rows`].
pub(crate) fn timed_run(
    b: &mut impl Bench,
    v: f64,
    seconds: f64,
    fields: &str,
    dt: f64,
) -> Result<u32, Error> {
    let t_acc = v.abs() / VELOCITY_ACC;
    let steps = ((seconds + 2.0 * t_acc + 0.01) / dt).ceil();
    // The fields per sample within the buffer's values (92 spare: 8100 of the F405's 8192).
    let room = capture_capacity(b)?.saturating_sub(92) as f64;
    let every = decimation(steps, fields.split(',').count(), room) as f64;
    let n = (steps / every).ceil() as u32;
    b.capture(fields, every as u32, n, true)?;
    primitive(b, velocity(v, Some((0.0, 1.0, 1.0, seconds))))?;
    b.wait(n as f64 * every * dt)?;
    capture_wait(b, 0.01, 200)?;
    check_faults(b)?;
    b.hold()?;
    Ok(every as u32)
}

/// Moves the axis to `x` \\[rad\\] (the protocol's position) in the position loop at up to `vel`
/// [rad/s] and waits until the move has ended; fails (the bridge off) on a fault or when it
/// has not ended in four times the time at `vel`.
pub fn move_to(b: &mut impl Bench, x: f64, vel: f64) -> Result<(), Error> {
    guarded(b, |b| {
        b.enable()?;
        let from = position(b)?;
        b.send(Command::Move {
            pos: x as f32,
            vel: Some(vel as f32),
        })?;
        // A quintic from rest to rest peaks at 1.875 × its mean speed: about twice the time
        // at `vel`; then up to twice that again.
        let t = 2.0 * (x - from).abs() / vel + 0.02;
        b.wait(t)?;
        for _ in 0..100 {
            if !status(b)?.moving {
                return check_faults(b);
            }
            b.wait(t / 50.0)?;
        }
        check_faults(b)?;
        Err(Error::Device(format!("the move to {x} rad did not end")))
    })
}

/// The axis's position from `status` \\[rad\\] (from the power-up position, as the stroke
/// limits `lim.pos_min`/`lim.pos_max` are).
pub fn position(b: &mut impl Bench) -> Result<f64, Error> {
    Ok(status(b)?.pos)
}

/// The device's soft stroke limits `(lim.pos_min, lim.pos_max)` \[rad\].
pub fn soft_limits(b: &mut impl Bench) -> Result<(f64, f64), Error> {
    Ok((
        get_param(b, ParamId::LimPosMin)?,
        get_param(b, ParamId::LimPosMax)?,
    ))
}

/// The device's stroke limits narrowed to `window` each way around where the axis is;
/// returns the previous ones.
pub fn narrow_limits(b: &mut impl Bench, window: f64) -> Result<(f64, f64), Error> {
    let (lo, hi) = soft_limits(b)?;
    let x = position(b)?;
    let (nlo, nhi) = ((x - window).max(lo), (x + window).min(hi));
    // Narrowing each side keeps pos_min < pos_max after each set.
    b.set(ParamId::LimPosMin, nlo)?;
    b.set(ParamId::LimPosMax, nhi)?;
    Ok((lo, hi))
}

/// The means of the columns of `rows`.
pub(crate) fn means(rows: &[Vec<f64>]) -> Vec<f64> {
    let n = rows.len().max(1) as f64;
    let w = rows.first().map_or(0, Vec::len);
    (0..w)
        .map(|c| rows.iter().map(|r| r[c]).sum::<f64>() / n)
        .collect()
}

/// Holds `amps` in current mode for `seconds` and returns the mean current \\[A\\] and voltage
/// \\[V\\] over its second half, and the position change \\[rad\\] over the whole.
pub(crate) fn hold_current(
    b: &mut impl Bench,
    amps: f64,
    seconds: f64,
    dt: f64,
) -> Result<(f64, f64, f64), Error> {
    let x0 = position(b)?;
    b.current(amps)?;
    b.wait(seconds / 2.0)?;
    // Two fields: at most half the buffer (and 2700 samples, 0.135 s at 20 kHz).
    let most = capture_capacity(b)?.div_euclid(2).clamp(2, 2700) as f64;
    let n = ((seconds / 2.0) / dt).ceil().clamp(2.0, most) as u32;
    let rows = capture_now(b, "current,volts", n, dt)?;
    check_faults(b)?;
    let m = means(&rows);
    Ok((m[0], m[1], position(b)? - x0))
}

#[cfg(test)]
mod tests {
    use super::decimation;

    /// The decimation keeps `steps / every` samples of `fields` fields within the room, with the
    /// least `every` that does: checked against a search over `every`.
    #[test]
    fn decimation_is_the_least_that_fits() {
        for steps in [1.0, 100.0, 8100.0, 8101.0, 16_200.0, 123_457.0] {
            for fields in 1..=4usize {
                for room in [2048.0, 4004.0, 8000.0, 8100.0] {
                    let every = decimation(steps, fields, room);
                    let fits = |e: u32| (steps / e as f64) * fields as f64 <= room;
                    assert!(fits(every), "{steps} {fields} {room}: {every}");
                    assert!(
                        every == 1 || !fits(every - 1),
                        "{steps} {fields} {room}: {every}"
                    );
                }
            }
        }
        assert_eq!(decimation(16_200.0, 1, 8100.0), 2);
        assert_eq!(decimation(0.0, 3, 8100.0), 1);
        assert_eq!(decimation(100.0, 1, 0.0), 1);
        assert_eq!(decimation(f64::NAN, 1, 8100.0), 1);
    }
}
