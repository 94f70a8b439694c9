//! Commissioning: the motor's R, k_e, J, L, the current sense's and the encoder's directions,
//! the breakaway, then the current and position loops' gains chosen from them.

use crate::Error;
use gms_core::drive::Faults;
use gms_core::protocol::Command;
use gms_core::protocol::ParamId;
use gms_ident::units::{num4, si};

use crate::client::{
    Bench, DeviceInfo, VELOCITY_ACC, capture_capacity, capture_now, capture_rows, capture_wait,
    check_configured, check_faults, get_param, guarded, hold_current, means, narrow_limits,
    position, primitive, rad_per_count, scales_line, timed_run,
};
use crate::estimate::{
    BridgeLoss, inductance_from_step, inertia_from_pulse, local_parabolas, ls_slope,
    resistance_and_loss, resistance_and_step,
};
use crate::settings::restoring;

/// What commissioning measured and decided.
#[derive(Debug, Clone, Default)]
pub struct Commissioned {
    /// The current sense's residual offset at rest, bridge off \[A\] (after the start-up zero).
    pub sense_offset: f64,
    /// Its noise at rest, one standard deviation per position step \[A\].
    pub sense_noise: f64,
    /// The current-sense polarity found (`sense.dir`) \[-\].
    pub sense_dir: f64,
    /// The encoder direction found (`enc.dir`) \[-\].
    pub enc_dir: f64,
    /// Winding resistance \[ohm\] (with the bridge's switches in the current's path).
    pub r: f64,
    /// The bridge's dead time \[s\] (`drive.dead_time`), from the step of the voltage the
    /// held currents need through zero current; 0 when there is none to see.
    pub dead_time: f64,
    /// Back-EMF constant [V·s/rad] (= k_M in SI).
    pub k_e: f64,
    /// Reflected inertia [kg·m²].
    pub inertia: f64,
    /// Winding inductance \[H\].
    pub inductance: f64,
    /// The current of the pulse that first slid the axis \[A\] (an upper bound of the
    /// breakaway current within a quarter of it; × k_M: the breakaway torque).
    pub breakaway_a: f64,
    /// The device's friction model scaled to the measured breakaway, when the axis broke away
    /// at more than 1.5 × (or less than 1/1.5 of) what the model expects: `gms.fs`, `gms.fc`,
    /// `gms.sigma`, `gms.c` and the block stiffnesses times one factor (the shape stays the
    /// model's until `identify`; the experiments that plan from the model then fit the axis).
    pub friction_scaled: Vec<(ParamId, f64)>,
    /// Current-loop PI from the bandwidth (`cur.kp` [V/A], `cur.ki` [V/(A·s)]).
    pub cur_pi: (f64, f64),
    /// The position loop's gains and their bounds (once that step has run).
    pub pos: Option<gms_ident::gains::PositionGains>,
    /// What was done, a line per step.
    pub lines: Vec<String>,
    /// Why the loop found is under the floor ([`MIN_PHASE_MARGIN`], [`MIN_GAIN_MARGIN`]), if
    /// it is: measured at rest after backing off, or (where the encoder hides the response)
    /// the model's. `gms-tune commission` does not apply such a loop unless forced.
    pub short_of_floor: Option<String>,
    /// A notch set for a resonance above the crossover that held the loop under the floor
    /// (its slot, 0 or 1, and the notch), found by [`crate::frf::suggest_notch`] from a
    /// sliding sweep of the open loop.
    pub notch: Option<(usize, gms_core::control::shaping::Notch)>,
}

/// The two notches' settings.
const NOTCH_KEYS: [[ParamId; 3]; 2] = [
    [
        ParamId::FiltNotch1FHz,
        ParamId::FiltNotch1Q,
        ParamId::FiltNotch1DepthDb,
    ],
    [
        ParamId::FiltNotch2FHz,
        ParamId::FiltNotch2Q,
        ParamId::FiltNotch2DepthDb,
    ],
];

impl Commissioned {
    /// The `[device]` settings, each with its parameter (its path: `.path()` or `Display`).
    pub fn settings(&self) -> Vec<(ParamId, f64)> {
        vec![
            (ParamId::SenseDir, self.sense_dir),
            (ParamId::EncDir, self.enc_dir),
            (ParamId::MotorR, self.r),
            (ParamId::DriveDeadTime, self.dead_time),
            (ParamId::MotorKE, self.k_e),
            (ParamId::MotorKM, self.k_e),
            (ParamId::FfInertia, self.inertia),
            (ParamId::CurKp, self.cur_pi.0),
            (ParamId::CurKi, self.cur_pi.1),
        ]
        .into_iter()
        .chain(self.pos.iter().flat_map(|g| g.sets()))
        .chain(self.friction_scaled.iter().copied())
        .chain(self.notch.iter().flat_map(|(slot, n)| {
            let k = NOTCH_KEYS[(*slot).min(1)];
            [
                (k[0], n.f_hz as f64),
                (k[1], n.q as f64),
                (k[2], n.depth_db as f64),
            ]
        }))
        .collect()
    }
}

/// What [`slide`] found: which way the encoder counts when the motor pushes, and the pulse
/// that broke the axis away.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Slide {
    /// The signed slide \[rad\] (negative: the encoder counts against the motor).
    pub moved: f64,
    /// The current of the pulse that moved the axis \[A\] (the one before it held): an
    /// upper bound of the breakaway current, within a quarter of it.
    pub amps: f64,
}

/// The dead times commissioning sets \[s\]: none up to a bridge's 5 µs (the parameter's
/// range, `drive.dead_time`).
pub const DEAD_TIME_RANGE: (f64, f64) = (0.0, 5e-6);

/// The least dead time commissioning takes as a bridge's \[s\] (the back-EMF runs then fit the
/// bridge's step with k_e): an ideal bridge reads 0.3 ns, a DRV8871 220 ns.
pub const DEAD_TIME_SEEN: f64 = 20e-9;

/// How far a pulse must move the axis to count as a slide \[rad\]: 2 mrad (beyond the
/// pre-sliding range, which a stiff or blocked axis travels too) or eight counts of the
/// encoder, whichever is more.
pub fn slide_threshold(rad_per_count: f64) -> f64 {
    (8.0 * rad_per_count).max(2e-3)
}

/// Which way the encoder counts when the motor pushes, and at what current the axis breaks
/// away: in current mode, pulses of current that the device ends by itself after 10 ms (so a
/// slow link cannot hold the current on a sliding axis), from half the expected breakaway
/// (the device's `gms.fs`) up by a quarter of it each to three times it, then on by a
/// quarter of the last each (an axis whose friction the device's model underestimates),
/// within 60 % of the current limit (a step to it overshoots in the current loop, and the
/// trip is at 1.5 × the limit or below), until the axis has slid ([`slide_threshold`]). Fails when
/// no current flows (a current friction holds, measured) or the axis does not slide.
pub fn slide(b: &mut impl Bench, dev: &DeviceInfo, dt: f64) -> Result<Slide, Error> {
    let i_fs = dev.fs / dev.k_m;
    let threshold = slide_threshold(rad_per_count(b)?);
    primitive(b, Command::Enable { current: true })?;
    b.current(0.0)?;
    b.wait(0.05)?;
    let x0 = position(b)?;
    let mut moved = 0.0;
    let mut amps = 0.5 * i_fs;
    let mut last = 0.0;
    while amps <= 0.6 * dev.i_max {
        primitive(
            b,
            Command::Current {
                amps: amps as f32,
                seconds: Some(0.01),
            },
        )?;
        b.wait(0.05)?;
        moved = position(b)? - x0;
        last = amps;
        if moved.abs() > threshold {
            break;
        }
        amps += 0.25 * if amps < 3.0 * i_fs { i_fs } else { amps };
    }
    b.current(0.0)?;
    b.wait(0.2)?;
    check_faults(b)?;
    if moved.abs() <= threshold {
        // Which of the two: a current friction holds (40 % of the expected breakaway).
        let (i, _, _) = hold_current(b, 0.4 * i_fs, 0.1, dt)?;
        b.current(0.0)?;
        if i < 0.2 * i_fs {
            return Err(Error::Device(format!(
                "commanded {:.4e} A, measured {i:.4e} A: no current flows (the motor not \
                 connected?)",
                0.4 * i_fs
            )));
        }
        return Err(Error::Device(format!(
            "the axis did not move with current pulses up to {} ({} N·m, 60 % of lim.i_max): \
             blocked?",
            si(last, "A"),
            num4(last * dev.k_m)
        )));
    }
    Ok(Slide { moved, amps: last })
}

/// Commissioning a motor on the bench: the current sense at rest (offset, noise); its
/// polarity (a reversed sense makes the current loop run away at once: `over_current`, then
/// `sense.dir` flipped and tried again); the encoder's direction (current steps of a quarter
/// of the expected Fs until the axis slides 2 mrad, which way the counts say; flipped by
/// `enc.dir`; each step a pulse of 10 ms the device ends by itself); the winding resistance and the
/// bridge's dead time (current mode at ±40, ±60 and ±80 % of the expected breakaway, the axis
/// held by friction: `v = R i + sign(i) (α − β / |i|)`, offsets cancelled); the
/// back-EMF constant (timed velocity runs at 1, 2 and 3 × `speed` each way: the voltage less
/// R × current against the speed, the slope); the reflected inertia (timed current pulses and
/// the coasts after them); the inductance (the current loop's step response). The device's
/// stroke limits are narrowed around the start for the run (the farthest speed run each way
/// and 0.5 rad more). The direction settings it changes to go on, and the limits, are put back
/// at the end (and on failure, with the bridge off): the caller applies the result.
pub fn commission(b: &mut impl Bench, speed: f64) -> Result<Commissioned, Error> {
    if !(speed > 0.0 && speed * 3.0 <= VELOCITY_MAX_BENCH) {
        return Err(Error::Params(format!(
            "speed {speed} rad/s: positive, three times it at most {VELOCITY_MAX_BENCH} rad/s"
        )));
    }
    check_configured(b)?;
    let scales = scales_line(b)?;
    let dev = DeviceInfo::read(b)?;
    let dt = dev.dt();
    check_faults(b)?;
    let dirs0 = (
        get_param(b, ParamId::SenseDir)?,
        get_param(b, ParamId::EncDir)?,
    );
    // The device's own stroke guard around the start: the farthest speed run each way, and
    // half a radian for the rest; an axis that runs away stops there with the bridge off.
    let v = 3.0 * speed;
    let window = 1.2 * (v * KE_RUN + v * v / VELOCITY_ACC) + 0.5;
    let gains0 = (
        get_param(b, ParamId::PosKp)?,
        get_param(b, ParamId::PosKi)?,
        get_param(b, ParamId::PosKd)?,
    );
    // The limits, the position gains (the back-EMF runs soften them) and the directions as
    // they were after, whatever happens: the caller applies what was found.
    restoring(b, |b| {
        narrow_limits(b, window)?;
        guarded(b, |b| commission_steps(b, &dev, dt, dirs0, gains0, speed))
    })
    .map(|mut c| {
        c.lines.insert(0, scales);
        c
    })
}

/// The share of the position integral carried as a friction level during the back-EMF
/// runs [-] (`pos.ki_fric`; the device's own is put back after them).
const KE_RUN_FRICTION_SHARE: f64 = 0.5;

/// The winding's L/R, as a share of the current loop's period, under which commissioning
/// warns that the sense reads the ripple under its mean \[-\]: on the simulated DRV8871 a
/// 14 Ω winding at 0.54 (measured; 0.49 true) read R +6.5 % and k_e +8.5 %; a 13.8 Ω one
/// (7.8 mN·m/A) at 0.48, 0.6, 0.68, 0.8 and 1.0 read R +8.4, +3.7, +2.3, +0.8 and −0.2 %; the
/// default motor at 0.9 R +0.03 %.
pub const FAST_WINDING: f64 = 0.8;

/// The derivative filter's corner during the back-EMF runs, as a division of its own \[-\]
/// (see the runs in [`commission`]).
pub const KE_RUN_D_FILTER_DIV: f64 = 16.0;

/// How many times the voltage the bridge's dead time takes (half its step at a reversal) the
/// back-EMF at the runs' top speed should reach \[-\]; under it commissioning warns that k_e is
/// uncertain.
pub const KE_EMF_OVER_STEP: f64 = 10.0;

/// The length of each back-EMF run at constant speed \[s\] (0.1 s settling, 0.3 s averaged).
/// With 0.1 s averaged, k_e on a coarse-encoder motor with ten times the modelled friction
/// (`hil-sim/tests/coarse.rs`: R 4.19 Ω, 2000 counts) read anywhere from +1 % to −6 % as a
/// one-ulp change of the duty's arithmetic moved the soft loop's ripple against the window;
/// with 0.3 s the ten motors' worst is under 1 %.
pub(crate) const KE_RUN: f64 = 0.4;

pub use gms_ident::gains::CURRENT_BW_FRACTION;

/// The fastest speed commissioning uses [rad/s] (the velocity mode allows 20).
pub(crate) const VELOCITY_MAX_BENCH: f64 = 20.0;

pub(crate) fn commission_steps(
    b: &mut impl Bench,
    dev: &DeviceInfo,
    dt: f64,
    (sense0, enc0): (f64, f64),
    (kp, ki, kd): (f64, f64, f64),
    speed: f64,
) -> Result<Commissioned, Error> {
    let mut c = Commissioned {
        sense_dir: sense0,
        enc_dir: enc0,
        ..Commissioned::default()
    };
    let i_fs = dev.fs / dev.k_m;
    // 1. The sense at rest, bridge off.
    b.disable()?;
    let rows = capture_now(b, "current", 2000, dt)?;
    let m = means(&rows)[0];
    let var = rows.iter().map(|r| (r[0] - m).powi(2)).sum::<f64>() / rows.len().max(1) as f64;
    (c.sense_offset, c.sense_noise) = (m, var.sqrt());
    c.lines.push(format!(
        "current sense at rest: offset {}, noise {} rms",
        si(c.sense_offset, "A"),
        si(c.sense_noise, "A")
    ));
    // 2. Its polarity: a small current in current mode.
    let mut polarity_ok = false;
    for attempt in 0..2 {
        let tried = (|| {
            primitive(b, Command::Enable { current: true })?;
            b.current(0.4 * i_fs)?;
            b.wait(0.02)
        })();
        // The runaway may trip while `enable current` is still being answered: the latched
        // fault says what happened either way.
        let faults = check_faults(b);
        match (tried, faults) {
            (Ok(()), Ok(())) => {
                polarity_ok = true;
                break;
            }
            (_, Err(e))
                if attempt == 0 && e.faults().is_some_and(|f| f.contains(Faults::OVER_CURRENT)) =>
            {
                c.sense_dir = -c.sense_dir;
                b.clear()?;
                b.set(ParamId::SenseDir, c.sense_dir)?;
                c.lines.push(
                    "current sense: reversed (the current loop ran away: over_current); sense.dir flipped"
                        .into(),
                );
            }
            (Err(e), _) | (_, Err(e)) => return Err(e),
        }
    }
    if !polarity_ok {
        return Err(Error::Device(
            "the current loop runs away either way".into(),
        ));
    }
    if c.sense_dir == sense0 {
        c.lines.push(format!(
            "current sense: polarity right (sense.dir {})",
            c.sense_dir
        ));
    }
    // 3. The encoder's direction.
    let sl = slide(b, dev, dt)?;
    let moved = sl.moved;
    // The experiments below need the breakaway current (the sense's polarity above only a
    // small current): the device's friction model's when the axis agrees with it, else the
    // pulse that moved it (a user's motor whose friction the model, Table 1 by default, is far
    // from).
    let expected = i_fs;
    let off = sl.amps > 1.5 * expected || sl.amps < expected / 1.5;
    let i_fs = if sl.amps > 1.5 * expected {
        c.lines.push(format!(
            "breakaway: the axis slid under a pulse of {}, {:.1} times what the device's \
             friction model expects (gms.fs {} N·m over motor.k_m {} N·m/A): the experiments \
             use the pulse's current",
            si(sl.amps, "A"),
            sl.amps / expected,
            num4(dev.fs),
            num4(dev.k_m)
        ));
        sl.amps
    } else {
        expected
    };
    c.breakaway_a = sl.amps;
    if moved < 0.0 {
        c.enc_dir = -c.enc_dir;
        // The bridge goes off with the change; back into current mode.
        b.set(ParamId::EncDir, c.enc_dir)?;
        primitive(b, Command::Enable { current: true })?;
        c.lines.push(format!(
            "encoder: counted {} under a positive current: reversed; enc.dir flipped",
            si(moved, "rad")
        ));
    } else {
        c.lines.push(format!(
            "encoder: direction right ({} under a positive current)",
            si(moved, "rad")
        ));
    }
    // 4. R and the bridge's dead time at standstill, friction holding the axis: ±40, ±60
    //    and ±80 % of the breakaway (the expected one, or three quarters of the pulse that
    //    slid it, the last one below it having held). The bridge loses sign(i) t_dead / T × V
    //    of every period's voltage, less what the current gives back slewing the switching
    //    node in the dead time (β / |i|); the status's volts are the duty's, the firmware's
    //    own compensation (`drive.dead_time`) included, so they carry the whole loss whatever
    //    it is set to: v = R i + sign(i) (α − β / |i|) over the six holds, t_dead = α T / V.
    //    (v = R i + c sign(i) over two magnitudes read the fall of the loss as resistance:
    //    R +4.8 % and k_e −8 % after it on a 7.5 Ω motor with a 10 pF node, +25 % with 100
    //    pF. Two holds, before that, read R + c / |i|: 24.6 Ω for 10.6.)
    let base = i_fs.min(0.75 * sl.amps);
    let mut holds = Vec::with_capacity(6);
    for share in [0.4, -0.4, 0.6, -0.6, 0.8, -0.8] {
        let (i, v, _) = hold_current(b, share * base, 0.2, dt)?;
        holds.push((i, v));
    }
    b.current(0.0)?;
    let (ip, in_) = (holds[0].0, holds[1].0);
    if (ip - in_).abs() < 0.2 * base {
        return Err(Error::Device(format!(
            "commanded ±{:.3e} A, measured {ip:.3e} and {in_:.3e} A: no current flows (the motor \
             not connected?)",
            0.4 * base
        )));
    }
    let unfit = || {
        Error::Device(format!(
            "the held currents do not fit a resistance: {holds:?} (A, V)"
        ))
    };
    let v_supply = get_param(b, ParamId::LimVSupply)?;
    let rate = get_param(b, ParamId::RateCurHz)?;
    // Where the bridge loses no dead time (an ideal one), the fading term's extra unknown
    // only adds the holds' noise to R (+0.44 % on the default motor against −0.14 % without
    // it, and k_e's plain slope below takes ten times that: −6.3 %): then `v = R i + c
    // sign(i)`.
    let loss = resistance_and_loss(&holds).ok_or_else(unfit)?;
    let loss = if loss.alpha / v_supply / rate > DEAD_TIME_SEEN {
        loss
    } else {
        let (r, alpha) = resistance_and_step(&holds).ok_or_else(unfit)?;
        BridgeLoss {
            r,
            alpha,
            beta: 0.0,
        }
    };
    // A resistance that is not positive is the holds' noise or motion, not a winding: an
    // error here, not a `set` the device refuses.
    if !(loss.r.is_finite() && loss.r > 0.0) {
        return Err(unfit());
    }
    c.r = loss.r;
    // The loss the holds saw at their largest current: what the speed runs below meet.
    let step = loss.alpha - loss.beta / holds[4].0.abs().max(f64::MIN_POSITIVE);
    let dead = loss.alpha / v_supply / rate;
    let (lo, hi) = DEAD_TIME_RANGE;
    // Under DEAD_TIME_SEEN the holds' noise, not a bridge (the ideal bridge read 0.12 ns and
    // was set so): none.
    c.dead_time = if dead > DEAD_TIME_SEEN {
        dead.clamp(lo, hi)
    } else {
        0.0
    };
    let held: Vec<String> = holds
        .iter()
        .map(|(i, v)| format!("{} at {}", si(*v, "V"), si(*i, "A")))
        .collect();
    c.lines.push(format!(
        "winding resistance: {} ({})",
        si(c.r, "Ω"),
        held.join(", ")
    ));
    // The node's capacitance that β gives (reported, not a parameter: the firmware's band
    // around zero current covers the range where the loss fades).
    let node = 2.0 * loss.beta / (v_supply * v_supply * rate);
    let fades = if loss.beta > 0.0 && dead > DEAD_TIME_SEEN {
        format!(
            ", less by {} at {} (a switching node of about {} slewed by the current)",
            si(loss.beta / holds[0].0.abs().max(f64::MIN_POSITIVE), "V"),
            si(holds[0].0.abs(), "A"),
            si(node, "F")
        )
    } else {
        String::new()
    };
    c.lines.push(if dead > hi {
        format!(
            "bridge dead time: {} from a loss of {} at large currents, more than a bridge's \
             {}: taken as {} (the sense's zero or the motor, not the bridge?)",
            si(dead, "s"),
            si(loss.alpha, "V"),
            si(hi, "s"),
            si(c.dead_time, "s")
        )
    } else if dead > DEAD_TIME_SEEN {
        format!(
            "bridge dead time: {} (the bridge loses {} of the voltage in the current's \
             direction at {} and {}{fades}): drive.dead_time",
            si(dead, "s"),
            si(loss.alpha, "V"),
            si(v_supply, "V"),
            si(rate, "Hz")
        )
    } else {
        format!(
            "bridge dead time: none seen ({} from a loss of {} in the current's direction, \
             under {}): drive.dead_time 0",
            si(dead, "s"),
            si(loss.alpha, "V"),
            si(DEAD_TIME_SEEN, "s")
        )
    });
    // 5. k_e from timed runs both ways: V - R i against the speed. The motor's inertia is
    //    not known yet, and a loop tuned for a heavier one may be unstable on it: the runs
    //    use a softer position loop (kp / 4, ki / 8, kd / 2, the derivative's filter at a
    //    sixteenth of its corner; `commission` puts them back), which tracks a constant speed
    //    well enough. (With the filter left at the default 8 kHz, a coarse encoder's count
    //    steps drive the bridge voltage in spikes, and k_e on the gear motor read 12 % low. At
    //    a quarter, they still swing the current through zero at the count rate, where a real
    //    bridge's dead time turns its loss over: over ten random gear motors with the real
    //    bridge, k_e read −7 to −59 % at a quarter, −15 and −25 % at worst with the loss
    //    taken out by the current's sign below, −12.7 % at an eighth, within ±4.5 % at a
    //    sixteenth; the ideal bridge within ±2.3 % at a sixteenth.)
    //    The runs alternate their direction, and the friction they meet is the motor's, not
    //    the device's model of it (a gear motor's is ten times Table 1's): a plain integral,
    //    still holding the last run's friction, unwinds it into the next run's samples (k_e
    //    read +5.2 % on a 2000-count motor of `hil-sim/tests/coarse.rs`). Half the integral
    //    carried as a friction level (`pos.ki_fric`) turns over with the direction.
    let d_filter = get_param(b, ParamId::PosDFilterHz)?;
    let share = get_param(b, ParamId::PosKiFric)?;
    // The dead-time compensation off for the runs: within its band (1 % of `lim.i_max`) it
    //    grows with the commanded current, which grows with the speed (viscous friction), and
    //    would bias the slope (k_e read +35 % on the gear motor of `hil-sim/tests/coarse.rs`
    //    with the real bridge); off, the bridge's loss is the step fitted below.
    let dead_time = get_param(b, ParamId::DriveDeadTime)?;
    b.set(ParamId::DriveDeadTime, 0.0)?;
    b.set(ParamId::PosKiFric, KE_RUN_FRICTION_SHARE)?;
    b.set(ParamId::PosKd, kd / 2.0)?;
    b.set(ParamId::PosKp, kp / 4.0)?;
    b.set(ParamId::PosKi, ki / 8.0)?;
    b.set(ParamId::PosDFilterHz, d_filter / KE_RUN_D_FILTER_DIV)?;
    b.hold()?;
    // The bridge's loss taken out of the runs' voltage, where step 4 saw one.
    let alpha = if dead > DEAD_TIME_SEEN {
        loss.alpha
    } else {
        0.0
    };
    let mut pts = Vec::new();
    for k in 1..=3 {
        for dir in [1.0, -1.0] {
            let v = dir * speed * k as f64;
            let t_acc = v.abs() / VELOCITY_ACC;
            let run = KE_RUN;
            // The current and the voltage as their means over each sample's steps: decimated
            // point samples alias the position loop's ripple at the encoder's count rate
            // into their means (a coarse encoder's k_e read 4 to 18 % low, depending on the
            // phase of the counts against the samples).
            // Beside a bridge's dead time, the current's sign too (`sign_mean`, every period
            //    counted): on a coarse encoder the loop swings the current through zero at the
            //    count rate, more often the faster it runs, and the bridge's loss is α times
            //    that mean, not α (k_e read −58 % on a 1.5 Ω gear motor of
            //    `hil-sim/tests/coarse.rs`: its current was negative 16, 32 and 44 % of the
            //    time at 5, 10 and 15 rad/s). With four fields at most, the time is the
            //    sample's index × its steps.
            let fields = "pos,current_mean,volts_mean,sign_mean";
            let every = f64::from(timed_run(b, v, run, fields, dt)?);
            // (t, pos, current, volts, sign)
            let rows: Vec<Vec<f64>> = capture_rows(b)?
                .into_iter()
                .enumerate()
                .map(|(j, r)| [&[j as f64 * every * dt], &r[..]].concat())
                .filter(|r| r.len() == 5 && r[0] >= t_acc + 0.1 && r[0] <= t_acc + run)
                .collect();
            if rows.len() < 2 {
                return Err(Error::Device("an empty capture".into()));
            }
            // The speed: the least-squares slope of the position.
            let m = means(&rows);
            let t: Vec<f64> = rows.iter().map(|r| r[0]).collect();
            let x: Vec<f64> = rows.iter().map(|r| r[1]).collect();
            let w = ls_slope(&t, &x, dt * dt).unwrap_or(0.0);
            pts.push((w, m[3] - c.r * m[2] - alpha * m[4]));
        }
    }
    // The derivative's filter back: the position gains' rule below starts from it.
    b.set(ParamId::PosDFilterHz, d_filter)?;
    b.set(ParamId::PosKiFric, share)?;
    b.set(ParamId::DriveDeadTime, dead_time)?;
    // With a bridge that loses a dead time (step 4 saw one), V − R i = k_e ω + c' sign(ω):
    //    the recorded volts are the duty's, and the bridge takes its share of them in the
    //    current's direction, which at speed is the motion's. c' is fitted with the slope
    //    (`resistance_and_step`), not taken from step 4: where the current's ripple crosses
    //    zero the loss is less than at the holds (subtracting the holds' step read k_e 19 to
    //    60 % low on `hil-sim/tests/coarse.rs`'s motors with the real bridge, the fit 2 to 10
    //    %; the plain slope +580 % on the default motor). Without one, the plain slope (the
    //    fit's extra unknown costs it up to 11 % on the coarse motors' scattered points).
    let (w, e): (Vec<f64>, Vec<f64>) = pts.iter().copied().unzip();
    let fit = if dead > DEAD_TIME_SEEN {
        resistance_and_step(&pts).map(|(k, _)| k)
    } else {
        ls_slope(&w, &e, f64::MIN_POSITIVE)
    };
    c.k_e = match fit {
        Some(k) if w.iter().any(|x| *x != w[0]) => k,
        _ => return Err(Error::Device("the speed runs did not move the axis".into())),
    };
    c.lines.push(format!(
        "back-EMF constant: {} from {} runs up to {} rad/s (k_M = k_e in SI)",
        si(c.k_e, "V·s/rad"),
        pts.len(),
        3.0 * speed
    ));
    // Beside a bridge's dead time the runs' back-EMF must stand well clear of its step: where
    // the current's ripple crosses zero the bridge loses less than the step, and the fit's
    // c' sign(ω) no longer takes all of it (k_e read −35 % on a coarse motor of
    // `hil-sim/tests/coarse.rs` with 0.12 V of back-EMF against a 0.106 V step).
    let emf = c.k_e * 3.0 * speed;
    if dead > DEAD_TIME_SEEN && emf < KE_EMF_OVER_STEP * step {
        let needed = KE_EMF_OVER_STEP * step / (3.0 * c.k_e.max(f64::MIN_POSITIVE));
        let remedy = if needed <= VELOCITY_MAX_BENCH / 3.0 {
            format!("commission again with --speed {needed:.3} or more if the stroke allows")
        } else {
            format!(
                "no speed the bench allows reaches it (--speed {:.3} at most): check k_e \
                 against the motor's datasheet (k_e = k_M in SI)",
                VELOCITY_MAX_BENCH / 3.0
            )
        };
        c.lines.push(format!(
            "  warning: the back-EMF at the runs' top speed is {}, under {KE_EMF_OVER_STEP} \
             times the voltage the bridge's dead time takes ({}): k_e is uncertain; {remedy}",
            si(emf, "V"),
            si(step, "V"),
        ));
    }
    // 6. The inertia: current pulses that the device ends by itself, and the coast after.
    c.inertia = inertia(b, &mut c, dev, dt, i_fs)?;
    // 7. The inductance: the current loop's step response at standstill.
    c.inductance = inductance(b, &mut c, dt, i_fs)?;
    // 8. The current loop's PI: kp as high as its delay allows with the rule's gain margin
    //    (the resistance's drop fed forward), the integral's corner five octaves below.
    let cur_hz = get_param(b, ParamId::RateCurHz)?;
    c.cur_pi = gms_ident::gains::current_pi(c.r, c.inductance, cur_hz);
    c.lines.push(format!(
        "current loop: cur.kp {} V/A, cur.ki {} V/(A·s) at {} ({:.1} dB of gain margin against \
         its 1.5 periods of delay)",
        num4(c.cur_pi.0),
        num4(c.cur_pi.1),
        si(cur_hz, "Hz"),
        -20.0 * gms_ident::gains::CURRENT_GAIN_MARGIN.log10()
    ));
    // 9. A friction model far from the axis scaled to its breakaway (the level measured, the
    //    shape the model's), for the gains below and for the caller to apply.
    let ratio = if off { sl.amps * c.k_e / dev.fs } else { 1.0 };
    if off {
        use ParamId::*;
        for p in [
            GmsFs, GmsFc, GmsSigma, GmsC, GmsK1, GmsK2, GmsK3, GmsK4, GmsK5, GmsK6,
        ] {
            let v = get_param(b, p)?;
            c.friction_scaled.push((p, v * ratio));
        }
        c.lines.push(format!(
            "friction level: the device's model scaled ×{ratio:.3} to the measured breakaway \
             ({} N·m: the pulse's current × k_M; its shape stays the model's until \
             `gms-tune identify`)",
            num4(sl.amps * c.k_e)
        ));
    }
    // 10. The position loop's gains for this motor and loop, kd between the device's
    //    friction model's Stribeck slope and the loops' stability limit.
    c.pos = Some(position_gains_for(b, &mut c, cur_hz, ratio)?);
    // 11. The loop as built, measured: the open loop at rest with what was found, its margins
    //     beside the model's; gains backed off while the phase margin is under
    //     MIN_PHASE_MARGIN.
    loop_check(b, &mut c, ratio)?;
    b.disable()?;
    Ok(c)
}

/// The least phase margin commissioning leaves \[deg\], measured at rest (the friction's
/// pre-sliding spring in the loop, where a loop's margins are least): below it, or below
/// [`MIN_GAIN_MARGIN`], the gains are backed off, and a loop still under it is not applied
/// unless forced. The floor of `gms_ident::margins`, which `gms-tune frf` warns under too.
pub const MIN_PHASE_MARGIN: f64 = gms_ident::margins::MIN_PHASE_MARGIN_DEG;

/// The least gain margin commissioning leaves \[dB\] (see [`MIN_PHASE_MARGIN`]).
pub const MIN_GAIN_MARGIN: f64 = gms_ident::margins::MIN_GAIN_MARGIN_DB;

/// Why the rule's loop `g` is under the floor by the linear model on the axis as measured,
/// if it is (for a loop that could not be measured).
fn modelled_short(g: &gms_ident::gains::PositionGains) -> Option<String> {
    let n = g.nominal;
    (n.over_floor() < 1.0).then(|| {
        format!(
            "the loop's modelled margins, {:.1}° and {:.2} dB at rest, {:.1}° and {:.2} dB \
             sliding, are under the floor of {MIN_PHASE_MARGIN}° and {MIN_GAIN_MARGIN} dB \
             (not measured)",
            n.rest.0, n.rest.1, n.sliding.0, n.sliding.1
        )
    })
}

/// The factor the position gains are backed off by, and how many times at most.
pub const BACK_OFF: (f64, usize) = (0.7, 3);

/// The position gains times [`BACK_OFF`]'s factor.
fn back_off(g: &mut gms_ident::gains::PositionGains) {
    g.kp *= BACK_OFF.0;
    g.ki *= BACK_OFF.0;
    g.kd *= BACK_OFF.0;
}

/// The modelled loop gain's margins for what `c` found (the linear model of
/// `gms_ident::linear` with the measured R, L, k_M, J, the friction model's pre-sliding
/// stiffness times `scale` and viscous term, and the device's settings `s` with the gains).
fn modelled_margins(
    c: &Commissioned,
    s: &gms_core::protocol::Settings,
    scale: f64,
    band: (f64, f64),
    amp: f64,
) -> Option<(crate::frf::Margins, f64)> {
    use gms_ident::linear::{LinearAxis, Operating, SmallSignal};
    let k_act: f64 = s.ff.actuator.blocks.iter().map(|b| b.k as f64).sum::<f64>() * scale;
    let ss = SmallSignal {
        r: c.r,
        l: c.inductance,
        k_m: c.k_e,
        k_e: c.k_e,
        j: c.inertia,
        two_mass: None,
        k_act,
        sigma_act: s.ff.actuator.sigma as f64 * scale,
        k_gw: 0.0,
        sigma_gw: 0.0,
        rad_per_count: s.rad_per_count() as f64,
    };
    let lin = LinearAxis::new(&ss, s, Operating::Rest).ok()?;
    let mut swing: f64 = 0.0;
    let l: Vec<(f64, num_complex::Complex64)> = (0..1000)
        .map(|i| {
            let f = band.0 * (band.1 / band.0).powf(i as f64 / 999.0);
            let z = lin.open_loop(f);
            // The position's response to the sine at the current command: P d / (1 + L).
            swing = swing.max((lin.plant(f) * amp / (1.0 + z)).norm());
            (f, num_complex::Complex64::new(z.re, z.im))
        })
        .collect();
    Some((crate::frf::margins(&l), swing / ss.rad_per_count))
}

/// Step 11: the gains found set (with the motor's figures and the current loop's PI), the
/// open loop measured at rest by a short sweep (`frf`, 20 points from 20 Hz to 0.4 × the
/// position rate), its margins printed beside the model's; while the measured phase margin
/// is under [`MIN_PHASE_MARGIN`] the position gains are backed off ([`BACK_OFF`]) and
/// measured again. A sweep that cannot be made (a coarse encoder that shows no response at
/// rest, a fault) is said and does not stop commissioning. The device's settings are put back
/// by the caller's snapshot.
fn loop_check(b: &mut impl Bench, c: &mut Commissioned, scale: f64) -> Result<(), Error> {
    use crate::frf::{Loop, Plan};
    let Some(mut g) = c.pos else {
        return Ok(());
    };
    let i_max = get_param(b, ParamId::LimIMax)?;
    let pos_hz = get_param(b, ParamId::RatePosHz)?;
    let mut plan = Plan::new(Loop::Open, 0.01 * i_max);
    plan.from_hz = 20.0;
    plan.to_hz = 0.4 * pos_hz;
    plan.points = 20;
    plan.seconds = 0.05;
    let mut notch_tried = false;
    for round in 0..=BACK_OFF.1 {
        let mut sets: Vec<(String, String)> = c
            .settings()
            .into_iter()
            .filter(|(k, _)| !k.path().starts_with("pos."))
            .map(|(k, v)| (k.to_string(), format!("{v}")))
            .collect();
        sets.extend(g.sets().map(|(k, v)| (k.to_string(), format!("{v}"))));
        // The model first, from the settings as they will be (nothing sent yet: an axis that
        // is not measured is left exactly as it was).
        let mut s = crate::settings::read(b)?;
        s.motor.r = c.r as f32;
        s.motor.k_m = c.k_e as f32;
        s.motor.k_e = c.k_e as f32;
        s.motor.inertia = c.inertia as f32;
        s.current.kp = c.cur_pi.0 as f32;
        s.current.ki = c.cur_pi.1 as f32;
        s.pid.kp = g.kp as f32;
        s.pid.ki = g.ki as f32;
        s.pid.kd = g.kd as f32;
        s.pid.d_filter_hz = g.d_filter_hz as f32;
        if let Some((slot, n)) = c.notch {
            s.shaping.notch[slot.min(1)] = n;
        }
        let model = modelled_margins(c, &s, scale, (plan.from_hz, plan.to_hz), plan.amplitude);
        if let Some((_, counts)) = model
            && counts < 3.0
        {
            c.lines.push(format!(
                "open loop: not measured (the model's position response to {} is {counts:.2} \
                 counts at most: the encoder's count would hide it)",
                si(plan.amplitude, "A")
            ));
            c.short_of_floor = modelled_short(&g);
            break;
        }
        let model = model.map(|m| m.0);
        crate::settings::apply(b, &sets, false)?;
        // From off: position control holding where the axis is (not the current mode the
        // steps before left it in).
        // A loop that is unstable at rest may trip while `enable` is being answered or in the
        // settling wait, not only in the sweep: each is the same trip, handled below.
        let mut pts = Vec::new();
        let measured = (|| {
            b.disable()?;
            b.clear()?;
            b.enable()?;
            b.wait(0.3)?;
            crate::frf::sweep(b, &plan, &mut pts, |_, _| {})
        })();
        let good = pts
            .iter()
            .filter(|p| p.coherence >= crate::frf::MIN_COHERENCE)
            .count();
        let m = match measured {
            Ok(()) if good >= pts.len() / 2 => {
                let l: Vec<(f64, num_complex::Complex64)> = pts
                    .iter()
                    .filter(|p| p.coherence >= crate::frf::MIN_COHERENCE)
                    .map(|p| (p.f_hz, p.value))
                    .collect();
                crate::frf::margins(&l)
            }
            Ok(()) => {
                c.lines.push(format!(
                    "open loop: not measured ({good} of {} points above the noise at rest: the \
                     encoder's count hides the response)",
                    pts.len()
                ));
                c.short_of_floor = modelled_short(&g);
                break;
            }
            Err(e) => {
                let _ = b.disable();
                // A trip is a fault the error names, or one the device latched that a
                // request's refusal only reports (`not enabled (fault)`).
                let tripped = e.faults().is_some() || check_faults(b).is_err();
                if !tripped || round == BACK_OFF.1 {
                    c.lines.push(format!("open loop: not measured ({e})"));
                    c.short_of_floor = if tripped {
                        Some(format!(
                            "the loop tripped at rest after backing off {} times ({e})",
                            BACK_OFF.1
                        ))
                    } else {
                        modelled_short(&g)
                    };
                    break;
                }
                c.lines.push(format!(
                    "open loop: the measurement tripped ({e}): gains backed off ×{}",
                    BACK_OFF.0
                ));
                back_off(&mut g);
                continue;
            }
        };
        let model_text = model.map_or("—".to_string(), |m| {
            format!(
                "{:.1}°, {:.2} dB, crossover {:.0} Hz",
                m.phase_margin_deg, m.gain_margin_db, m.crossover_hz
            )
        });
        c.lines.push(format!(
            "open loop at rest (kp {}, kd {}): measured phase margin {:.1}° (at {:.0} Hz), \
             gain margin {:.2} dB, crossover {:.0} Hz; modelled {model_text}",
            num4(g.kp),
            num4(g.kd),
            m.phase_margin_deg,
            m.phase_margin_hz,
            m.gain_margin_db,
            m.crossover_hz
        ));
        let pm_ok = m.phase_margin_deg >= MIN_PHASE_MARGIN || m.phase_margin_deg.is_nan();
        let gm_ok = m.gain_margin_db >= MIN_GAIN_MARGIN;
        if pm_ok && gm_ok {
            c.short_of_floor = None;
            break;
        }
        c.short_of_floor = Some(format!(
            "the loop's margins at rest, {:.1}° and {:.2} dB, are under the floor of \
             {MIN_PHASE_MARGIN}° and {MIN_GAIN_MARGIN} dB",
            m.phase_margin_deg, m.gain_margin_db
        ));
        // Once, before backing the gains off: a resonance above the crossover (a compliant
        // stage's mode) that a notch takes out, found from the loop sliding (at rest the
        // friction's pre-sliding spring makes a bump of its own, which a notch must not take:
        // it is the sliding loop's crossover region).
        if !notch_tried && c.notch.is_none() {
            notch_tried = true;
            match sliding_notch(b, &s, &plan, pos_hz) {
                Ok(sug)
                    if sug.after.phase_margin_deg >= MIN_PHASE_MARGIN
                        && sug.after.gain_margin_db >= MIN_GAIN_MARGIN =>
                {
                    c.lines.push(format!(
                        "  a resonance at {:.0} Hz ({:+.1} dB) above the crossover: notch {} at \
                         {:.0} Hz, q {}, {} dB (sliding, predicted {:.1}° and {:.2} dB from \
                         {:.1}° and {:.2} dB); measured again",
                        sug.resonance.0,
                        sug.resonance.1,
                        sug.slot + 1,
                        sug.notch.f_hz,
                        sug.notch.q,
                        sug.notch.depth_db,
                        sug.after.phase_margin_deg,
                        sug.after.gain_margin_db,
                        sug.before.phase_margin_deg,
                        sug.before.gain_margin_db
                    ));
                    c.notch = Some((sug.slot, sug.notch));
                    continue;
                }
                Ok(sug) => c.lines.push(format!(
                    "  no notch: the best for the resonance at {:.0} Hz predicts {:.1}° and \
                     {:.2} dB sliding",
                    sug.resonance.0, sug.after.phase_margin_deg, sug.after.gain_margin_db
                )),
                Err(e) => c.lines.push(format!("  no notch: {e}")),
            }
        }
        if round == BACK_OFF.1 {
            c.lines.push(format!(
                "  warning: the margins are still under {MIN_PHASE_MARGIN}° and \
                 {MIN_GAIN_MARGIN} dB after backing off {} times (a resonance? gms-tune frf \
                 --loop open --suggest)",
                BACK_OFF.1
            ));
            break;
        }
        c.lines.push(format!(
            "  warning: margins under {MIN_PHASE_MARGIN}° and {MIN_GAIN_MARGIN} dB: position \
             gains backed off ×{}",
            BACK_OFF.0
        ));
        back_off(&mut g);
    }
    // (The caller switches the bridge off after this step.)
    c.pos = Some(g);
    Ok(())
}

/// The notch `gms-tune frf --loop open --suggest` would give for the loop as set on the
/// device (`s` its settings): the open loop swept sliding at 1 rad/s (five times the default
/// friction's Stribeck velocity, within the stroke commissioning leaves) from 200 Hz to 0.22
/// of the position rate with `rest`'s amplitude.
fn sliding_notch(
    b: &mut impl Bench,
    s: &gms_core::protocol::Settings,
    rest: &crate::frf::Plan,
    pos_hz: f64,
) -> Result<crate::frf::Suggestion, String> {
    let mut plan = rest.clone();
    plan.velocity = Some(1.0);
    plan.from_hz = 200.0;
    plan.to_hz = 0.22 * pos_hz;
    plan.points = 40;
    let mut pts = Vec::new();
    let swept = (|| {
        b.disable()?;
        b.clear()?;
        b.enable()?;
        b.wait(0.3)?;
        crate::frf::sweep(b, &plan, &mut pts, |_, _| {})?;
        b.disable()
    })();
    if let Err(e) = swept {
        let _ = b.disable();
        return Err(format!("the sliding sweep did not run ({e})"));
    }
    crate::frf::suggest_notch(&pts, &s.shaping, pos_hz)
}

/// The position loop's gains for the motor `c` measured, the current loop at `cur_hz` with
/// its new PI, the device's position rate, derivative filter, supply and friction model (its
/// level times `scale`).
pub(crate) fn position_gains_for(
    b: &mut impl Bench,
    c: &mut Commissioned,
    cur_hz: f64,
    scale: f64,
) -> Result<gms_ident::gains::PositionGains, Error> {
    use gms_ident::gains::{Axis, SlidingCurve, position_gains};
    let mut k0 = 0.0;
    use ParamId::*;
    for p in [GmsK1, GmsK2, GmsK3, GmsK4, GmsK5, GmsK6] {
        k0 += scale * get_param(b, p)?;
    }
    let axis = Axis {
        r: c.r,
        l: c.inductance,
        k_m: c.k_e,
        inertia: c.inertia,
        cur_pi: c.cur_pi,
        cur_hz,
        pos_hz: get_param(b, ParamId::RatePosHz)?,
        d_filter_hz: get_param(b, ParamId::PosDFilterHz)?,
        v_supply: get_param(b, ParamId::LimVSupply)?,
        k_presliding: k0,
        rad_per_count: rad_per_count(b)?,
        i_max: get_param(b, ParamId::LimIMax)?,
    };
    let s = SlidingCurve {
        fs: scale * get_param(b, ParamId::GmsFs)?,
        fc: scale * get_param(b, ParamId::GmsFc)?,
        vs: get_param(b, ParamId::GmsVs)?,
        delta: get_param(b, ParamId::GmsDelta)?,
        sigma: scale * get_param(b, ParamId::GmsSigma)?,
    };
    let g = position_gains(&axis, &s).ok_or_else(|| {
        Error::Device(format!(
            "no position-loop gains for the measured motor ({axis:?}): the loop model does not \
             settle"
        ))
    })?;
    c.lines.push(format!(
        "position loop: pos.kp {} N·m/rad, pos.ki {} N·m/(rad·s), pos.kd {} N·m·s/rad, \
         pos.d_filter_hz {} Hz (natural frequency {:.0} Hz)",
        num4(g.kp),
        num4(g.ki),
        num4(g.kd),
        num4(g.d_filter_hz),
        (g.kp / c.inertia).sqrt() / (2.0 * std::f64::consts::PI)
    ));
    let (n, w) = (g.nominal, g.worst);
    c.lines.push(format!(
        "  modelled margins: at rest {:.1}° and {:.2} dB, sliding {:.1}° and {:.2} dB; the \
         least over the pre-sliding stiffness ×0.5…×2 and the inertia ±20 %: {:.1}° and {:.2} dB \
         at rest, {:.1}° and {:.2} dB sliding",
        n.rest.0, n.rest.1, n.sliding.0, n.sliding.1, w.rest.0, w.rest.1, w.sliding.0, w.sliding.1
    ));
    if g.count_limited {
        c.lines.push(format!(
            "  limited by the encoder's count ({}): one count of error asks at most {:.0} % \
             of lim.i_max through kp, a one-count step {:.0} % through kd",
            si(axis.rad_per_count, "rad"),
            100.0 * gms_ident::gains::COUNT_SHARE.0,
            100.0 * gms_ident::gains::COUNT_SHARE.1
        ));
    }
    c.lines.push(format!(
        "  kd above the friction's negative damping {} (the device's Stribeck curve at Vs: \
         Fs {}, Fc {}, Vs {}) by ×{:.2}; below the stability limit {} by ×{:.2}",
        num4(g.kd_min),
        si(s.fs, "N·m"),
        si(s.fc, "N·m"),
        si(s.vs, "rad/s"),
        g.margin_low(),
        num4(g.kd_max),
        g.margin_high()
    ));
    if g.kd_max <= g.kd_min {
        c.lines.push(
            "  warning: no kd is both above the friction's negative damping and stable: kd is \
             set for stability, the axis may hunt at low speed (a faster current loop or more \
             inertia widens the window)"
                .into(),
        );
    }
    Ok(g)
}

/// The reflected inertia from current pulses, timed on the device, each way twice, and the
/// coast that follows: at the same speed the friction is the same in both, so
/// J = k_M × i / (a_pulse − a_coast), the accelerations from local parabolas through the
/// captured positions, compared at 30-80 % of the top speed. The pulses and the parabolas are
/// sized for the encoder ([`InertiaPlan::for_encoder`]): 3 × the breakaway current for 2 ms and
/// 7-sample parabolas on a fine one; on a coarse one (a count above 20 µrad) 1.5 × for 20 ms,
/// parabolas over 6 ms, so that quantisation averages out.
pub(crate) fn inertia(
    b: &mut impl Bench,
    c: &mut Commissioned,
    dev: &DeviceInfo,
    dt: f64,
    i_fs: f64,
) -> Result<f64, Error> {
    let k_m = c.k_e;
    let plan = InertiaPlan::for_encoder(rad_per_count(b)?, dt);
    let amps = (plan.breakaways * i_fs).min(0.8 * dev.i_max);
    let pulse = plan.pulse;
    let mut js = Vec::new();
    // Three fields: at most a third of the buffer.
    let n = ((plan.record / dt).ceil() as u32).min(capture_capacity(b)? / 3);
    primitive(b, Command::Enable { current: true })?;
    b.wait(0.05)?;
    for dir in [1.0, -1.0, 1.0, -1.0] {
        b.capture("t,pos,current", 1, n, true)?;
        primitive(
            b,
            Command::Current {
                amps: (dir * amps) as f32,
                seconds: Some(pulse as f32),
            },
        )?;
        b.wait(n as f64 * dt)?;
        capture_wait(b, 0.01, 200)?;
        check_faults(b)?;
        let rows = capture_rows(b)?;
        b.wait(0.05)?;
        // Speed and acceleration at each sample (local parabolas), then J from the pulse and
        // the coast.
        let t: Vec<f64> = rows.iter().map(|r| r[0]).collect();
        let x: Vec<f64> = rows.iter().map(|r| dir * r[1]).collect();
        let va: Vec<(f64, f64, f64, f64)> = local_parabolas(&t, &x, plan.half_window)
            .into_iter()
            .map(|(t, v, a, k)| (t, v, a, dir * rows[k][2]))
            .collect();
        js.push(
            inertia_from_pulse(&va, pulse, plan.edge, k_m).map_err(|e| Error::Device(e.into()))?,
        );
    }
    b.current(0.0)?;
    let j = js.iter().sum::<f64>() / js.len() as f64;
    c.lines.push(format!(
        "reflected inertia: {} kg·m² from four current pulses of {} for {} ms and the coasts \
         after (each {} … {})",
        num4(j),
        si(amps, "A"),
        pulse * 1e3,
        num4(js.iter().cloned().fold(f64::INFINITY, f64::min)),
        num4(js.iter().cloned().fold(f64::NEG_INFINITY, f64::max))
    ));
    Ok(j)
}

/// How `inertia` pulses the axis for an encoder.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InertiaPlan {
    /// The pulse's current in breakaway currents \[-\].
    pub breakaways: f64,
    /// The pulse's length \[s\].
    pub pulse: f64,
    /// The record from the pulse's start \[s\] (the pulse and the coast).
    pub record: f64,
    /// The local parabolas' half width \[samples\].
    pub half_window: usize,
    /// How far from the pulse's ends a parabola's centre keeps \[s\] (its half width on a
    /// coarse encoder, so that none straddles the switch; 0 on a fine one).
    pub edge: f64,
}

impl InertiaPlan {
    /// The plan for an encoder of `rad_per_count` \[rad\] sampled every `dt` \[s\]: on the
    /// paper's (3.8 µrad) or any finer than 20 µrad, 3 × the breakaway for 2 ms, recorded 30
    /// ms, 7-sample parabolas; on a coarser one, 1.5 × for 20 ms (about 50 counts of a 3 mrad
    /// count on a motor that its breakaway accelerates at 1500 rad/s²), recorded 60 ms,
    /// parabolas over 6 ms.
    pub fn for_encoder(rad_per_count: f64, dt: f64) -> InertiaPlan {
        if rad_per_count <= 20e-6 {
            InertiaPlan {
                breakaways: 3.0,
                pulse: 0.002,
                record: 0.03,
                half_window: 3,
                edge: 0.0,
            }
        } else {
            let h = ((0.003 / dt).round() as usize).max(3);
            InertiaPlan {
                breakaways: 1.5,
                pulse: 0.02,
                record: 0.06,
                half_window: h,
                edge: h as f64 * dt,
            }
        }
    }
}

/// The winding inductance from the current loop's response to current steps at standstill
/// (between −40 % and +40 % of the expected breakaway current: friction holds the axis, no
/// back-EMF), sixteen steps each way in turn, averaged (the loop is linear, so a step of 2A
/// from −A is twice the response to A from rest), against the device's own current loop
/// (`gms_core`'s controller with the device's gains, rates, supply and feedforward R) driving
/// an R-L winding whose voltage is applied one current period late, as the bridge does: the L
/// whose simulated response is closest (least squares over the first 2 ms, golden-section
/// search over ln L). A winding much faster than the current period settles within it and
/// shows little of its L: below L/R = a sixth of the period the result is flagged.
pub(crate) fn inductance(
    b: &mut impl Bench,
    c: &mut Commissioned,
    dt: f64,
    i_fs: f64,
) -> Result<f64, Error> {
    // Steps between two currents of one sign, 10 % and 60 % of the breakaway: at standstill
    // the current's ripple decays towards zero in each brake but never crosses it, so the
    // bridge loses the same dead time in every period, a constant voltage the loop's
    // integral holds and the steps' differences cancel: the loop the fit below simulates is
    // linear. (Steps through zero cross the dead time's step, which no linear fit follows:
    // with the compensation for it on they read L -15 % on the default motor with the real
    // bridge, where its band and the ripple meet; uncompensated, the image with a 350 ns
    // bridge read 15.2 mH for 0.3 mH, `rehost/tests/bench.rs`.) The compensation is off
    // for the steps: it would add a step of its own within its band. (The fit's voltage is
    // the period's mean over the whole period; a pulse centred on the period, decaying half
    // a period to the sample, read L -15 % instead of -2.8 %: the bridge's 0.7 µs delay and
    // the amplifier's lag bring the pulse that much nearer the sample.) Each pair of steps
    // (up, then down) takes the other sign than the last, so that the torque averages to
    // nothing: all of one sign, between 10 and 70 %, the axis reached the guard on a loaded
    // machine in CI (L -2.8 % then, -6.1 % alternating, the ideal bridge +1.6 %).
    let (lo, hi) = (0.1 * i_fs, 0.6 * i_fs);
    let amps = hi - lo;
    let n = 20u32;
    let steps = 16;
    let mut avg = vec![0.0f64; n as usize];
    let dead_time = get_param(b, ParamId::DriveDeadTime)?;
    b.set(ParamId::DriveDeadTime, 0.0)?;
    primitive(b, Command::Enable { current: true })?;
    for k in 0..steps {
        let sign = if (k / 2) % 2 == 0 { 1.0 } else { -1.0 };
        let up = k % 2 == 0;
        if up {
            // The pair's start, settled (through zero from the last pair's, outside the
            // capture).
            b.current(sign * lo)?;
            b.wait(0.01)?;
        }
        let (from, to) = if up { (lo, hi) } else { (hi, lo) };
        b.capture("current", 1, n, true)?;
        b.current(sign * to)?;
        b.wait(n as f64 * dt)?;
        capture_wait(b, 0.01, 200)?;
        check_faults(b)?;
        for (a, r) in avg.iter_mut().zip(capture_rows(b)?) {
            // The response from `from` towards `to`, as a rise from 0 to `amps`.
            let rise = (sign * r[0] - from) * (to - from).signum();
            *a += rise / steps as f64;
        }
        b.wait(0.002)?;
    }
    b.current(0.0)?;
    b.set(ParamId::DriveDeadTime, dead_time)?;
    // The device's current loop, as it runs.
    let mut p = gms_core::device::default_settings();
    p.current.kp = get_param(b, ParamId::CurKp)? as f32;
    p.current.ki = get_param(b, ParamId::CurKi)? as f32;
    p.cur_rate_hz = get_param(b, ParamId::RateCurHz)? as f32;
    p.pos_rate_hz = get_param(b, ParamId::RatePosHz)? as f32;
    p.v_supply = get_param(b, ParamId::LimVSupply)? as f32;
    p.motor.r = get_param(b, ParamId::MotorR)? as f32;
    let r = c.r;
    let h = 1.0 / p.cur_rate_hz as f64;
    let l = inductance_from_step(&avg, amps, r, &p).map_err(|e| Error::Device(e.into()))?;
    c.lines.push(format!(
        "winding inductance: {} from the current loop's response to {steps} steps of {} \
         (L/R {:.1} µs)",
        si(l, "H"),
        si(amps, "A"),
        l / r * 1e6
    ));
    if l / r < h / 6.0 {
        c.lines.push(format!(
            "  warning: L/R is below a sixth of the current period ({:.1} µs): the winding \
             settles within a period, so L is poorly resolved (cur.kp = ωL matters little there)",
            h / 6.0 * 1e6
        ));
    } else if l / r < FAST_WINDING * h {
        c.lines.push(format!(
            "  warning: L/R is under {FAST_WINDING} of the current period ({:.1} µs): the \
             current's ripple decays within the period, and the sense's window at the \
             counter's bottom reads under the period's mean: R and k_e read high (+6.5 % and \
             +8.5 % at half the period on the simulated DRV8871, R +2.3 % at 0.68); a faster current loop \
             (rate.cur_hz) or an inductor in series resolves it",
            FAST_WINDING * h * 1e6
        ));
    }
    Ok(l)
}
