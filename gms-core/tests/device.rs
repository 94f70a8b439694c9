//! The device core's control loop on its own: missed periods.

use gms_core::device::{
    Board, ControlLoop, Inputs, Requests, calibrate_sense, default_settings, prepare,
};
use gms_core::drive::Faults;

/// The F405 board (gms-core's description), its bridge driving at once on `enable` (its
/// supply divider reads 12 V in [`board_device`]'s link).
fn board() -> Board {
    Board {
        bridge_wake_s: 0.0,
        ..gms_core::boards::f405::BOARD
    }
}

/// A capture buffer for a test's loop.
fn buffer() -> &'static mut [f32] {
    Box::leak(vec![0.0; 8192].into_boxed_slice())
}

/// Requests in storage of their own (the loop takes them by reference).
fn leak(r: Requests) -> &'static mut Requests {
    Box::leak(Box::new(r))
}

/// Storage for a controller (a loop's running one, a front's spare).
fn ctrl_buf() -> gms_core::device::CtrlBuf {
    Box::leak(Box::new(
        prepare(&default_settings(), &board()).unwrap().ctrl,
    ))
}

/// A loop at rest at count 0, zero current.
fn rest() -> ControlLoop {
    let b = board();
    let a = prepare(&default_settings(), &b).unwrap();
    let zero = calibrate_sense(&b, 3.4, || Some(codes(2048)));
    ControlLoop::new(b, a, zero.sense, zero.faults, 0, buffer(), ctrl_buf())
}

/// The default current loop's PWM period at the F405's 168 MHz \[cycles\].
fn period_cycles() -> u32 {
    (168e6 / default_settings().cur_rate_hz) as u32
}

/// The sum of the board's conversions, each at `code`.
fn codes(code: u32) -> u32 {
    board().sense_oversample * code
}

/// One PWM period at rest, `since_last` cycles after the last; a request is stepped on
/// until the loop takes it (in the last current step of a position period).
fn step(lp: &mut ControlLoop, since_last: u32, req: Option<Requests>) {
    let mut req = req.map(leak);
    let mut since_last = since_last;
    loop {
        let inp = Inputs {
            encoder: 0,
            current_codes: codes(2048),
            since_last,
        };
        lp.step(inp, |_, _| req.take());
        lp.finish(1000, false);
        if req.is_none() {
            break;
        }
        since_last = period_cycles();
    }
}

/// Arms a capture of `spec` in one step at rest, `period` cycles after the last.
fn arm_capture(lp: &mut ControlLoop, period: u32, spec: gms_core::device::CaptureSpec) {
    use gms_core::device::CaptureRequest;
    step(
        lp,
        period,
        Some(Requests {
            capture: Some(CaptureRequest::Arm(spec)),
            ..Requests::default()
        }),
    );
}

/// The capture's first 64 values, read back through the requests' chunk (given back at the
/// next exchange), in PWM periods at rest `period` cycles apart.
fn read_capture(lp: &mut ControlLoop, period: u32) -> gms_core::device::Chunk {
    use gms_core::device::CaptureRequest;
    let mut chunk = None;
    let mut req = Some(leak(Requests {
        capture: Some(CaptureRequest::Read { start: 0, max: 64 }),
        ..Requests::default()
    }));
    for _ in 0..4 {
        let inp = Inputs {
            encoder: 0,
            current_codes: codes(2048),
            since_last: period,
        };
        lp.step(inp, |_, h| {
            if let Some(r) = h.returned {
                chunk = Some(r.chunk);
            }
            req.take()
        });
    }
    chunk.expect("a chunk")
}

#[test]
fn a_missed_period_is_counted_and_latches_overrun_while_driving() {
    let period = period_cycles();
    let mut lp = rest();
    // Disabled: steps far apart (a flash erase holds the CPU for seconds) count nothing.
    step(&mut lp, 0, None);
    step(&mut lp, 1000 * period, None);
    assert_eq!(lp.status().stats.missed(), 0);
    assert_eq!(lp.faults(), Faults::NONE);
    // Enabled, on time (with jitter): nothing.
    let enable = Requests {
        enable: true,
        ..Requests::default()
    };
    step(&mut lp, period, Some(enable));
    for k in 0..100u32 {
        step(&mut lp, period - 300 + 6 * k, None);
    }
    assert!(lp.enabled());
    assert_eq!(lp.status().stats.missed(), 0);
    // Two periods missed: counted, overrun latched, the bridge off at once.
    step(&mut lp, 3 * period, None);
    assert_eq!(lp.status().stats.missed(), 2);
    assert!(lp.faults().contains(Faults::OVERRUN), "{:?}", lp.faults());
    assert!(!lp.enabled());
}

/// A step that wrote its duty past the update it was for (the shell's timer reading): while
/// disabled nothing; while driving counted as `late` (not as a missed period), overrun
/// latched and the bridge off at once, even though its length was within budget.
#[test]
fn a_late_step_latches_overrun_while_driving() {
    let period = period_cycles();
    let mut lp = rest();
    step(&mut lp, 0, None);
    assert!(!lp.finish(1000, true));
    assert_eq!((lp.status().stats.late(), lp.faults()), (0, Faults::NONE));
    let enable = Requests {
        enable: true,
        ..Requests::default()
    };
    step(&mut lp, period, Some(enable));
    for _ in 0..10 {
        step(&mut lp, period, None);
        assert!(!lp.finish(1000, false));
    }
    assert!(lp.enabled());
    step(&mut lp, period, None);
    assert!(lp.finish(1000, true), "the bridge off now");
    let st = lp.status();
    assert_eq!((st.stats.late(), st.stats.missed()), (1, 0));
    assert!(lp.faults().contains(Faults::OVERRUN), "{:?}", lp.faults());
    assert!(!lp.enabled());
}

/// The board's deadman halts the loop from outside the step: the bridge off, `control_stall`
/// latched and in the status, and an `enable` refused while it stays latched.
/// A period's reading from a sense buffer the next sequence had begun to overwrite (the
/// board's step started too late): while driving, `overrun` and the bridge off; at rest,
/// nothing.
#[test]
fn a_stale_sense_reading_latches_overrun_while_driving() {
    let mut lp = rest();
    lp.sense_stale();
    step(&mut lp, period_cycles(), None);
    assert!(lp.status().faults.is_empty());
    step(
        &mut lp,
        period_cycles(),
        Some(Requests {
            enable: true,
            ..Requests::new()
        }),
    );
    assert!(lp.enabled());
    lp.sense_stale();
    let out = {
        let inp = Inputs {
            encoder: 0,
            current_codes: codes(2048),
            since_last: period_cycles(),
        };
        lp.step(inp, |_, _| None)
    };
    assert!(!out.enabled && out.compare == (0, 0), "{out:?}");
    assert!(lp.status().faults.contains(Faults::OVERRUN));
}

#[test]
fn a_halt_from_the_deadman_switches_off_and_says_so() {
    let period = period_cycles();
    let mut lp = rest();
    let enable = || Requests {
        enable: true,
        ..Requests::default()
    };
    step(&mut lp, period, Some(enable()));
    for _ in 0..40 {
        step(&mut lp, period, None);
    }
    assert!(lp.enabled());
    lp.halt(Faults::CONTROL_STALL);
    assert!(!lp.enabled());
    for _ in 0..40 {
        step(&mut lp, period, None);
    }
    assert!(lp.status().faults.contains(Faults::CONTROL_STALL));
    step(&mut lp, period, Some(enable()));
    assert!(!lp.enabled(), "a latched stall keeps the bridge off");
    let mut names = String::new();
    lp.faults().write_names(&mut names).unwrap();
    assert_eq!(names, "control_stall");
}

#[test]
fn after_enable_the_bridge_wakes_in_brake_before_control() {
    let mut b = board();
    b.bridge_wake_s = 1e-3;
    let a = prepare(&default_settings(), &b).unwrap();
    let zero = calibrate_sense(&b, 3.4, || Some(codes(2048)));
    let mut lp = ControlLoop::new(b, a, zero.sense, zero.faults, 0, buffer(), ctrl_buf());
    let period = period_cycles();
    let mut req = Some(leak(Requests {
        enable: true,
        ..Requests::default()
    }));
    // The axis reads 5 counts off its hold point: control would drive at once.
    let mut outs = Vec::new();
    for _ in 0..80 {
        let inp = Inputs {
            encoder: if outs.iter().any(|o: &gms_core::device::Outputs| o.enabled) {
                5
            } else {
                0
            },
            current_codes: codes(2048),
            since_last: period,
        };
        let o = lp.step(inp, |_, _| req.take());
        lp.finish(1000, false);
        outs.push(o);
    }
    let arr = lp.timing().1;
    // 1 ms of brake from the step that takes the `enable` (both inputs high for the whole
    // period, but for the single count at the top on the PWM side), duty 0: 40 periods at
    // the default 40 kHz.
    let wake = (1e-3 * default_settings().cur_rate_hz).round() as usize;
    let on = outs.iter().position(|o| o.enabled).expect("enabled");
    assert!(on < 2, "{on}");
    for (k, o) in outs.iter().enumerate().skip(on).take(wake) {
        assert!(o.enabled, "{k}");
        assert_eq!(o.duty, 0.0, "{k}");
        assert!(
            o.compare.0 >= arr && o.compare.1 >= arr,
            "{k}: {:?}",
            o.compare
        );
    }
    // Then the loop controls: the 5-count error gives a duty.
    assert!(outs[on + wake..].iter().any(|o| o.duty != 0.0));
    assert_eq!(lp.faults(), Faults::NONE);
}

#[test]
fn capture_field_lists() {
    use gms_core::device::capture_fields;
    assert_eq!(capture_fields("t,pos,current"), Ok(([0, 1, 5, 0], 3)));
    assert_eq!(capture_fields("friction"), Ok(([6, 0, 0, 0], 1)));
    assert_eq!(capture_fields("t,ref,error,ff"), Ok(([0, 2, 3, 4], 4)));
    assert_eq!(
        capture_fields("current,current_mean"),
        Ok(([5, 8, 0, 0], 2))
    );
    assert_eq!(
        capture_fields("pos,current_mean,volts_mean,sign_mean"),
        Ok(([1, 8, 9, 10], 4))
    );
    for bad in ["", "t,", ",t", "t,,pos", "speed", "t,pos,ref,error,ff", "T"] {
        assert!(capture_fields(bad).is_err(), "{bad:?}");
    }
}

#[test]
fn a_capture_records_what_the_loop_saw() {
    use gms_core::device::{CaptureSpec, CaptureState};
    let period = period_cycles();
    let mut lp = rest();
    // Every 2nd position step, pos and current, 10 samples, at once.
    let spec = CaptureSpec {
        fields: [1, 5, 0, 0],
        nfields: 2,
        every: 2,
        samples: 10,
        on_next: false,
    };
    arm_capture(&mut lp, period, spec);
    for _ in 0..60 {
        step(&mut lp, period, None);
    }
    let st = lp.status();
    assert_eq!((st.capture, st.captured), (CaptureState::Done, 10));
    // Read back: position 0 (at rest), current 0.
    let c = read_capture(&mut lp, period);
    assert_eq!((c.start, c.samples, c.nfields), (0, 10, 2));
    assert!(c.values[..20].iter().all(|v| *v == 0.0));
}

/// `current_mean` is the boxcar over the steps a decimated sample stands for (every step
/// counted once), `current` the sampled step's alone: a current alternating +1/−1 A from step
/// to step, recorded every 4th step, reads +1 (the sampled step's sign) against a mean of 0;
/// a ramp reads its block's mean.
#[test]
fn current_mean_is_the_boxcar_of_the_decimated_steps() {
    use gms_core::device::{Capture, CaptureSpec, StepValues};
    let mut cap = Capture::new(vec![0.0f32; 64]);
    cap.arm(CaptureSpec {
        fields: [5, 8, 0, 0],
        nfields: 2,
        every: 4,
        samples: 8,
        on_next: false,
    });
    // Steps 0..16 alternate, then 16..32 ramp 0, 1, 2, …
    let current = |k: u64| {
        if k < 16 {
            if k % 2 == 0 { 1.0 } else { -1.0 }
        } else {
            (k - 16) as f32
        }
    };
    for k in 0..40u64 {
        cap.step(&StepValues {
            steps: k,
            dt: 5e-5,
            rad_per_count: 3.8e-6,
            current: current(k),
            current_period: current(k),
            periods: 1,
            ..StepValues::default()
        });
    }
    let c = cap.read(0, 8);
    assert_eq!(c.samples, 8);
    // Sample 0 is the trigger's step alone; sample j > 0 is step 4j, standing for steps
    // 4j-3 ..= 4j.
    assert_eq!((c.values[0], c.values[1]), (1.0, 1.0));
    for j in 1..8usize {
        let k = 4 * j as u64;
        let mean = (k - 3..=k).map(current).sum::<f32>() / 4.0;
        assert_eq!(c.values[2 * j], current(k), "sample {j}");
        assert!(
            (c.values[2 * j + 1] - mean).abs() < 1e-6,
            "sample {j}: {}",
            c.values[2 * j + 1]
        );
    }
    // The alternating part: sampled +1 (even steps), its mean 0.
    assert_eq!((c.values[2], c.values[3]), (1.0, 0.0));
}

/// `sign_mean` is the mean of the measured current's sign over every PWM period a sample
/// stands for: a current that alternates +300 and −100 codes from period to period (two
/// periods a position step) reads a sign of 0 and a mean current of +100 codes' worth; held at
/// −100 codes it reads −1.
#[test]
fn sign_mean_counts_each_periods_current_direction() {
    use gms_core::device::{CaptureSpec, CaptureState};
    let period = period_cycles();
    let mut lp = rest();
    let s = default_settings();
    assert_eq!((s.cur_rate_hz / s.pos_rate_hz).round(), 2.0);
    let spec = CaptureSpec {
        fields: [8, 10, 5, 0],
        nfields: 3,
        every: 1,
        samples: 20,
        on_next: false,
    };
    arm_capture(&mut lp, period, spec);
    let run = |lp: &mut ControlLoop, code: &dyn Fn(usize) -> u32, n: usize| {
        for k in 0..n {
            let inp = Inputs {
                encoder: 0,
                current_codes: codes(code(k)),
                since_last: period,
            };
            lp.step(inp, |_, _| None);
            lp.finish(1000, false);
        }
    };
    // 10 position steps alternating, then 10 held negative.
    run(&mut lp, &|k| if k % 2 == 0 { 2348 } else { 1948 }, 20);
    run(&mut lp, &|_| 1948, 20);
    for _ in 0..4 {
        step(&mut lp, period, None);
    }
    let st = lp.status();
    assert_eq!((st.capture, st.captured), (CaptureState::Done, 20));
    let c = read_capture(&mut lp, period);
    let row = |j: usize| (c.values[3 * j], c.values[3 * j + 1], c.values[3 * j + 2]);
    // The held part: the sampled current is −100 codes' worth, the sign −1.
    let (mean_neg, sign_neg, i_neg) = row(15);
    assert!(i_neg < 0.0 && (mean_neg - i_neg).abs() < 1e-6 * i_neg.abs());
    assert_eq!(sign_neg, -1.0);
    // The alternating part (the first sample is the trigger's step alone): sign 0, and the
    // current's mean a third of the +300 codes' current (−100 and +300 over two).
    for j in 1..9 {
        let (mean, sign, _) = row(j);
        assert_eq!(sign, 0.0, "sample {j}");
        assert!(
            (mean - (-3.0 * i_neg + i_neg) / 2.0).abs() < 1e-3 * i_neg.abs(),
            "sample {j}: {mean} against {}",
            (-3.0 * i_neg + i_neg) / 2.0
        );
    }
}

/// `current AMPS SECONDS`: the current held for so many position steps, then 0 A, still in
/// current mode (a pulse the device ends whatever the link does).
#[test]
fn a_timed_current_ends_on_the_device() {
    let mut lp = rest();
    let period = period_cycles();
    step(
        &mut lp,
        period,
        Some(Requests {
            enable: true,
            current: Some(0.0),
            ..Requests::default()
        }),
    );
    // PWM periods (calls) per position step: the current loop's rate over the position's.
    let s = default_settings();
    let per = (s.cur_rate_hz / s.pos_rate_hz).round() as usize;
    // (Requests are taken at a position step: every `per`-th call.)
    for _ in 1..per {
        step(&mut lp, period, None);
    }
    // 0.1 A for 25 position steps.
    step(
        &mut lp,
        period,
        Some(Requests {
            current: Some(0.1),
            current_steps: Some(25),
            ..Requests::default()
        }),
    );
    let mut cmds = Vec::new();
    for _ in 0..120 {
        step(&mut lp, period, None);
        cmds.push(lp.status().drive);
    }
    let held: Vec<f32> = cmds
        .iter()
        .map(|d| match d {
            gms_core::device::Drive::Current(a) => *a,
            _ => f32::NAN,
        })
        .collect();
    // 25 steps are 25 × `per` calls at 0.1 A (give or take the step the request lands in).
    let on = held.iter().filter(|a| **a == 0.1).count();
    assert!(
        (25 * per - per..=25 * per + per).contains(&on),
        "{on} periods at 0.1 A: {held:?}"
    );
    assert!(held[25 * per + 10..].iter().all(|a| *a == 0.0), "{held:?}");
    assert!(lp.enabled());
}

/// A `save` holds the CPU for up to 2 s (a flash erase): the first step after it sees the
/// whole motion of that time as one increment. Checked against the periods that really
/// elapsed, an axis that drifted at a legal 50 rad/s (half the board's 100 rad/s) is no
/// encoder jump; one that moved faster than the board allows over that time still is.
#[test]
fn an_encoder_increment_is_checked_against_the_periods_that_elapsed() {
    let period = period_cycles();
    let rpc = default_settings().rad_per_count() as f64;
    let stall_s = 2.0;
    let moved = |speed: f64| (speed * stall_s / rpc) as u32;
    for (speed, jump) in [(50.0, false), (150.0, true)] {
        let mut lp = rest();
        // Position steps come every other PWM step (10 kHz of 20 kHz): settle the phase.
        for _ in 0..4 {
            step(&mut lp, period, None);
        }
        assert_eq!(lp.faults(), Faults::NONE);
        // The stall: the next steps come 2 s later, the counter far away.
        let far = moved(speed);
        for k in 0..2 {
            let inp = Inputs {
                encoder: far,
                current_codes: codes(2048),
                since_last: if k == 0 {
                    (stall_s * 168e6) as u32
                } else {
                    period
                },
            };
            lp.step(inp, |_, _| None);
            lp.finish(1000, false);
        }
        assert_eq!(
            lp.faults().contains(Faults::ENCODER_JUMP),
            jump,
            "{speed} rad/s: {:?}",
            lp.faults()
        );
    }
}

#[test]
fn a_new_encoder_resolution_or_sense_scale_switches_the_bridge_off_and_rescales() {
    let b = board();
    let mut lp = rest();
    // One position step (the loop takes requests at position steps only: every other PWM
    // period here).
    let run = |lp: &mut ControlLoop, encoder: u32, codes: u32, req: Option<Requests>| {
        let mut req = req.map(leak);
        let inp = Inputs {
            encoder,
            current_codes: codes,
            since_last: period_cycles(),
        };
        while let Some(r) = req.take() {
            let mut once = Some(r);
            lp.step(inp, |_, _| once.take());
            lp.finish(1000, false);
            req = once;
        }
        lp.step(inp, |_, _| None);
        lp.finish(1000, false);
    };
    let enable = Requests {
        enable: true,
        ..Requests::default()
    };
    // 100 codes above the zero in each of the 16 conversions.
    let codes = codes(2148);
    run(&mut lp, 0, codes, Some(enable));
    for _ in 0..4 {
        run(&mut lp, 7, codes, None);
    }
    assert!(lp.enabled());
    let before = lp.status();
    assert_eq!(before.pos, 7);
    let per_code = 3.3f32 / 4095.0 / 3.4;
    assert!((before.current - 100.0 * per_code).abs() < 1e-6 * 100.0 * per_code);
    // A gear motor's encoder (2000 counts/rev) and a 15 mohm × 50 sense.
    let mut s = default_settings();
    s.counts_per_rev = 2000.0;
    s.sense_v_per_a = 0.75;
    let a = prepare(&s, &b).unwrap();
    let ctrl = ctrl_buf();
    *ctrl = a.ctrl;
    let apply = Requests {
        apply: Some(gms_core::device::Staged {
            ctrl,
            limits: a.limits,
            psc: a.psc,
            arr: a.arr,
            taken: false,
        }),
        ..Requests::default()
    };
    run(&mut lp, 7, codes, Some(apply));
    run(&mut lp, 7, codes, None);
    assert!(!lp.enabled(), "a new scale must switch the bridge off");
    let after = lp.status();
    // The same count, read as 7 × 2π/2000 rad from the power-up position.
    assert_eq!(after.pos, 7);
    assert_eq!(
        lp.controller().params().rad_per_count(),
        (std::f64::consts::TAU / 2000.0) as f32
    );
    let per_code = 3.3f32 / 4095.0 / 0.75;
    assert!((after.current - 100.0 * per_code).abs() < 1e-6 * 100.0 * per_code);
    // The limits follow: the trip under the new sense range (1.5 × lim.i_max; the range is
    // 2047 × 1.07 mA = 2.2 A), a following-error limit of at least 64 counts (0.2 rad).
    let l = b.limits(&s);
    assert!((l.i_trip - 1.5 * s.i_max).abs() < 1e-6, "{}", l.i_trip);
    assert!((l.max_error - 64.0 * std::f32::consts::TAU / 2000.0).abs() < 1e-6);
    // 100 rad/s over a position period: at 20 kHz 5 mrad = 1.59 counts of 3.14 mrad, so 2
    // (at 10 kHz 3.18, so 4).
    let per_step = 100.0 / f64::from(s.pos_rate_hz) / (std::f64::consts::TAU / 2000.0);
    assert_eq!(l.max_step_counts, per_step.ceil() as i64);
}

#[test]
fn the_default_encoder_is_the_papers_exactly() {
    let s = default_settings();
    assert_eq!(s.rad_per_count(), 3.8e-6f32);
    // Whole counts per revolution read back as set (the radians per count are derived).
    for cpr in [4.0f32, 1320.0, 2000.0, 4096.0, 65_536.0, 1e6, 1e9] {
        let mut s = default_settings();
        s.counts_per_rev = cpr;
        assert_eq!(s.counts_per_rev, cpr);
        let back = std::f64::consts::TAU / s.rad_per_count() as f64;
        assert!((back / cpr as f64 - 1.0).abs() < 1e-7, "{cpr}: {back}");
    }
}

/// A device core in one thread: waiting on the loop runs it one PWM period, at rest.
struct InlineLink {
    lp: ControlLoop,
    mb: gms_core::device::Mailbox,
    t_us: u64,
    /// The supply divider's code its ADC register holds (none: 0).
    supply: Option<u32>,
}

impl gms_core::device::LoopLink for InlineLink {
    fn with_mailbox<R>(&mut self, f: impl FnOnce(&mut gms_core::device::Mailbox) -> R) -> R {
        f(&mut self.mb)
    }
    fn now_us(&self) -> u64 {
        self.t_us
    }
    fn pause(&mut self) {
        let inp = Inputs {
            encoder: 0,
            current_codes: codes(2048),
            since_last: period_cycles(),
        };
        let mb = &mut self.mb;
        self.lp.step(inp, |st, c| mb.exchange(st, c));
        self.lp.finish(1000, false);
        self.t_us += (1e6 / default_settings().cur_rate_hz) as u64;
    }
    fn supply_code(&mut self) -> u32 {
        self.supply.unwrap_or(0)
    }
}

/// A store in memory.
struct MemStore(Option<[u8; gms_core::device::RECORD_LEN]>);

impl gms_core::device::ParamStore for MemStore {
    fn save(
        &mut self,
        rec: &[u8; gms_core::device::RECORD_LEN],
    ) -> Result<(), gms_core::device::StoreError> {
        self.0 = Some(*rec);
        Ok(())
    }
    fn load(
        &mut self,
    ) -> Result<Option<[u8; gms_core::device::RECORD_LEN]>, gms_core::device::StoreError> {
        Ok(self.0)
    }
}

/// A board's device from its store as `startup` decides, as the firmware builds it.
fn board_device(
    stored: Option<[u8; gms_core::device::RECORD_LEN]>,
) -> gms_core::device::Front<InlineLink, MemStore> {
    board_device_at(stored, 2048)
}

/// As [`board_device`], its current sense's zero calibrated at `zero` \[code\].
fn board_device_at(
    stored: Option<[u8; gms_core::device::RECORD_LEN]>,
    zero: u32,
) -> gms_core::device::Front<InlineLink, MemStore> {
    board_device_with(board(), stored, zero)
}

/// As [`board_device`] on board `b`.
fn board_device_on(
    b: Board,
    stored: Option<[u8; gms_core::device::RECORD_LEN]>,
) -> gms_core::device::Front<InlineLink, MemStore> {
    board_device_with(b, stored, 2048)
}

fn board_device_with(
    b: Board,
    stored: Option<[u8; gms_core::device::RECORD_LEN]>,
    zero: u32,
) -> gms_core::device::Front<InlineLink, MemStore> {
    use gms_core::device::{Front, ParamStore as _, startup};
    let mut store = MemStore(stored);
    let defaults = default_settings();
    let start = startup(store.load(), &defaults, &b, &mut |_| {}).unwrap();
    let zero = calibrate_sense(&b, start.settings.sense_v_per_a, || Some(codes(zero)));
    let lp = ControlLoop::new(
        b,
        start.applied,
        zero.sense,
        zero.faults,
        0,
        buffer(),
        ctrl_buf(),
    );
    // The loop's status published from the start, as every shell does before the first step.
    let mb = gms_core::device::Mailbox {
        status: lp.status(),
        ..gms_core::device::Mailbox::new()
    };
    let link = InlineLink {
        lp,
        mb,
        t_us: 0,
        supply: b.supply.map(|_| supply_code(12.0)),
    };
    Front::new(
        link,
        store,
        b,
        start.settings,
        defaults,
        leak(Requests::new()),
        ctrl_buf(),
    )
    .with_configured(start.configured, false)
}

fn ask(dev: &mut gms_core::device::Front<InlineLink, MemStore>, line: &str) -> String {
    let mut out = String::new();
    let mut reader = gms_core::protocol::LineReader::default();
    for b in line.bytes().chain(std::iter::once(b'\n')) {
        if let Some(l) = reader.push(b) {
            gms_core::protocol::execute(dev, l, &mut out).unwrap();
        }
    }
    out
}

#[test]
fn a_board_on_its_built_in_defaults_says_it_was_never_configured() {
    let mut dev = board_device(None);
    assert!(ask(&mut dev, "status").contains(" configured=0"));
    assert!(ask(&mut dev, "set enc.counts_per_rev 1320").starts_with("ok"));
    assert!(ask(&mut dev, "status").contains(" configured=1"));
    assert_eq!(ask(&mut dev, "get enc.counts_per_rev").trim(), "ok 1320");
    assert!(ask(&mut dev, "save").starts_with("ok"));
    // `defaults` puts the built-in set back: never configured again.
    assert!(ask(&mut dev, "defaults").starts_with("ok"));
    assert!(ask(&mut dev, "status").contains(" configured=0"));
    // A power-up on the saved record: configured, with its resolution.
    let (_, store) = dev.into_parts();
    let mut dev = board_device(store.0);
    assert!(ask(&mut dev, "status").contains(" configured=1"));
    assert_eq!(ask(&mut dev, "get enc.counts_per_rev").trim(), "ok 1320");
    // Out of range: refused, nothing changed.
    assert!(ask(&mut dev, "set enc.counts_per_rev 2").starts_with("err"));
    assert!(ask(&mut dev, "set sense.v_per_a 0").starts_with("err"));
    assert_eq!(ask(&mut dev, "get enc.counts_per_rev").trim(), "ok 1320");
}

/// A board that found at start it must not drive (its brown-out reset not set) refuses
/// `enable` and `enable current` with the reason, and does nothing else differently.
#[test]
fn a_board_refusing_to_drive_refuses_enable_with_its_reason() {
    let why = "brown-out reset not at 2.7 V";
    let mut dev = board_device(None).refusing_to_drive(Some(why));
    assert_eq!(ask(&mut dev, "enable").trim(), format!("err 8 {why}"));
    assert_eq!(
        ask(&mut dev, "enable current").trim(),
        format!("err 8 {why}")
    );
    assert!(ask(&mut dev, "status").contains(" enabled=0"));
    assert!(ask(&mut dev, "set pos.kp 0.5").starts_with("ok"));
    let mut dev = board_device(None).refusing_to_drive(None);
    assert!(ask(&mut dev, "enable").starts_with("ok"));
}

/// The status states the board's duty limit and counts the current steps it held: a
/// current the loop cannot reach (the sense reads zero) drives the duty to the F405's 0.43
/// at 40 kHz and no further.
#[test]
fn the_status_says_when_the_duty_limit_binds() {
    use gms_core::device::LoopLink as _;
    use gms_core::device::StatusReply;
    let mut dev = board_device(None);
    let read = |dev: &mut gms_core::device::Front<InlineLink, MemStore>| {
        let reply = ask(dev, "status");
        StatusReply::parse(reply.trim().strip_prefix("ok ").unwrap()).unwrap()
    };
    let st = read(&mut dev);
    let dmax = board().sense.duty_max(default_settings().cur_rate_hz);
    assert!(
        (st.duty_max - dmax).abs() < 1e-3 && (dmax - 0.43).abs() < 0.01,
        "{st:?}"
    );
    assert_eq!(st.duty_limited, 0);
    assert!(ask(&mut dev, "enable current").starts_with("ok"));
    assert!(ask(&mut dev, "current 0.3").starts_with("ok"));
    for _ in 0..400 {
        dev.link_mut().pause();
    }
    let st = read(&mut dev);
    assert!(st.duty_limited > 100, "{st:?}");
    assert!((st.duty.abs() - dmax).abs() < 1e-3, "{st:?}");
}

#[test]
fn the_device_s_status_reads_back_as_its_state() {
    use gms_core::device::{DriveKind, StatusReply};
    let mut dev = board_device(None);
    // A request the loop takes (its first step publishes the state).
    assert!(ask(&mut dev, "clear").starts_with("ok"));
    let reply = ask(&mut dev, "status");
    let text = reply.trim().strip_prefix("ok ").unwrap();
    let st = StatusReply::parse(text).unwrap();
    let d = default_settings();
    assert_eq!(st.mode, d.ff.mode);
    assert!(!st.enabled && !st.moving && !st.configured, "{text}");
    // A first start on no record: the defaults run, nothing latched.
    assert_eq!(st.faults, Faults::NONE, "{text}");
    assert_eq!(st.drive, DriveKind::Position);
    // The sense's zero from 16 conversions at code 2048 each.
    assert_eq!(st.sense_offset, 2048.0);
    assert_eq!((st.pos, st.current), (0.0, 0.0));
    assert!(ask(&mut dev, "set enc.counts_per_rev 1320").starts_with("ok"));
    let reply = ask(&mut dev, "status");
    let st = StatusReply::parse(reply.trim().strip_prefix("ok ").unwrap()).unwrap();
    assert!(st.configured);
}

/// The over-current trip within reach whatever the calibrated zero: for a zero anywhere in
/// the calibration's window (2048 ± 150 codes) and any current limit, the trip's reading from
/// the zero lies inside the INA240's linear range (0.2 V, 248 codes, inside each rail), so the
/// ADC shows it before it clips; at 2048 the trip is 0.95 of the hand-computed reach, the
/// nearer rail's room (4095 - 2048 - 0.2/3.3·4095 codes) × 3.3/4095/3.4 A = 0.4264 A.
#[test]
fn the_over_current_trip_is_within_the_senses_linear_range_from_any_zero() {
    let b = board();
    let margin = 0.2 / 3.3 * 4095.0;
    let apc = 3.3 / 4095.0 / 3.4;
    for zero in (1898..=2198).step_by(10) {
        for i_max in [0.05f32, 0.2, 0.4, 0.6, 2.0] {
            let mut s = default_settings();
            s.i_max = i_max;
            let a = prepare(&s, &b).unwrap();
            let z = calibrate_sense(&b, 3.4, || Some(codes(zero)));
            assert_eq!(z.faults, Faults::NONE, "{zero}");
            let lp = ControlLoop::new(b, a, z.sense, z.faults, 0, buffer(), ctrl_buf());
            let trip_codes = lp.limits().i_trip / apc;
            let z = zero as f32;
            assert!(
                z + trip_codes <= 4095.0 - margin + 0.01 && z - trip_codes >= margin - 0.01,
                "zero {zero}, i_max {i_max}: trip {} A ({trip_codes} codes)",
                lp.limits().i_trip
            );
            assert!(lp.limits().i_trip <= 1.5 * i_max);
        }
    }
    let reach = (4095.0 - 2048.0 - margin) * apc;
    assert!((reach - 0.4264).abs() < 1e-4, "{reach}");
    let lp = rest();
    assert!(
        (lp.limits().i_trip - 0.95 * reach).abs() < 1e-4,
        "{:?}",
        lp.limits()
    );
}

/// A zero 150 codes off (the window's edge) leaves the sense 0.391 A each way: `enable` with
/// the default 0.4 A limit is refused, saying why, and nothing drives; with `lim.i_max` below
/// the reach it enables. At 2048 the default enables.
#[test]
fn enable_is_refused_when_the_sense_cannot_reach_the_current_limit() {
    let mut dev = board_device_at(None, 2198);
    assert_eq!(
        ask(&mut dev, "enable").trim_end(),
        "err 8 lim.i_max beyond what the current sense reaches from its zero"
    );
    assert!(ask(&mut dev, "status").contains(" enabled=0 "));
    assert_eq!(ask(&mut dev, "set lim.i_max 0.38").trim_end(), "ok");
    assert_eq!(ask(&mut dev, "enable").trim_end(), "ok");
    let mut dev = board_device_at(None, 2048);
    assert_eq!(ask(&mut dev, "enable").trim_end(), "ok");
}

/// The analog watchdog at the ends of the INA240's linear range (0.2 V inside each rail of the
/// 3.3 V, 4095-code ADC: 248.18 and 3846.82 codes, worked out here by hand): 248 and 3847 are
/// past it, 249 and 3846 inside. Every trip from any calibrated zero lies inside (so a current
/// within the trip never sets it); an ideal sense (no margin) keeps one code inside each end,
/// so that 0 and the top code always count; a margin past the middle leaves nothing inside.
#[test]
fn the_sense_watchdog_sits_at_the_amplifiers_linear_range() {
    let b = board();
    assert_eq!(b.sense.watchdog_codes(4095), (249, 3846));
    for (code, past) in [(248, true), (249, false), (3846, false), (3847, true)] {
        assert_eq!(b.sense.watchdog_trips(code, 4095), past, "{code}");
    }
    let margin = 0.2 / 3.3 * 4095.0;
    assert!(248.0 < margin && margin < 249.0);
    assert!(3846.0 < 4095.0 - margin && 4095.0 - margin < 3847.0);
    // The trip from every zero the calibration accepts: inside the thresholds.
    let apc = 3.3 / 4095.0 / 3.4;
    for zero in (1898..=2198).step_by(10) {
        let a = prepare(&default_settings(), &b).unwrap();
        let z = calibrate_sense(&b, 3.4, || Some(codes(zero)));
        let lp = ControlLoop::new(b, a, z.sense, z.faults, 0, buffer(), ctrl_buf());
        let trip_codes = lp.limits().i_trip / apc;
        let (hi, lo) = (zero as f32 + trip_codes, zero as f32 - trip_codes);
        assert!(
            !b.sense.watchdog_trips(hi as u32, 4095)
                && !b.sense.watchdog_trips(lo as u32 + 1, 4095),
            "zero {zero}: the trip's codes {lo}..{hi} reach the watchdog"
        );
    }
    let ideal = gms_core::device::SenseChain {
        linear_margin_v: 0.0,
        ..b.sense
    };
    assert_eq!(ideal.watchdog_codes(4095), (1, 4094));
    assert!(ideal.watchdog_trips(0, 4095) && ideal.watchdog_trips(4095, 4095));
    assert!(!ideal.watchdog_trips(1, 4095) && !ideal.watchdog_trips(4094, 4095));
    let none = gms_core::device::SenseChain {
        linear_margin_v: 2.0,
        ..b.sense
    };
    for code in [0, 1, 2048, 4094, 4095] {
        assert!(none.watchdog_trips(code, 4095), "{code}");
    }
}

/// A conversion at an end of the ADC's range (the shell's analog watchdog): while disabled
/// nothing; while driving `over_current` latched and the bridge off before the step.
#[test]
fn a_clipped_conversion_latches_over_current_while_driving() {
    let period = period_cycles();
    let mut lp = rest();
    step(&mut lp, 0, None);
    lp.sense_clipped();
    assert_eq!(lp.faults(), Faults::NONE);
    let enable = Requests {
        enable: true,
        ..Requests::default()
    };
    step(&mut lp, period, Some(enable));
    assert!(lp.enabled());
    lp.sense_clipped();
    assert!(!lp.enabled());
    assert!(
        lp.faults().contains(Faults::OVER_CURRENT),
        "{:?}",
        lp.faults()
    );
}

/// A speed profile asked for while one runs at the same speed continues the reference
/// without a jump: the front plans it ahead to the step the loop first works out with it,
/// and the loop catches up only with what a later take adds. Over the take the reference
/// advances by the steps' count times the constant increment (a profile a step ahead or
/// behind would jump by a whole step's, 43,000 sub-counts at 0.05 rad/s).
#[test]
fn a_speed_profile_taken_later_continues_the_reference_without_a_jump() {
    continues_the_reference("velocity 0.05");
}

/// `request` twice over: the reference over the second take advances by the steps' count
/// times the constant increment.
fn continues_the_reference(request: &str) {
    use gms_core::device::LoopLink as _;
    let mut dev = board_device(None);
    assert!(ask(&mut dev, "enable").starts_with("ok"));
    assert!(ask(&mut dev, request).starts_with("ok"));
    // At its constant speed (a speed's ramp takes 1 ms, a move's jerk-limited one longer).
    for _ in 0..4000 {
        dev.link_mut().pause();
    }
    // Sampled at one phase of the position period: just after a position step.
    let at = |dev: &mut gms_core::device::Front<InlineLink, MemStore>| {
        let s = dev.link_mut().lp.status().steps;
        while dev.link_mut().lp.status().steps == s {
            dev.link_mut().pause();
        }
        let st = dev.link_mut().lp.status();
        (st.steps, st.reference.pos)
    };
    let (s0, p0) = at(&mut dev);
    let (s1, p1) = at(&mut dev);
    assert_eq!(
        s1,
        s0 + 1,
        "one position step per two periods at the defaults"
    );
    let inc = p1 - p0;
    assert!(inc > 40_000, "{inc} sub-counts a step");
    for _ in 0..3 {
        let (sa, pa) = at(&mut dev);
        assert!(ask(&mut dev, request).starts_with("ok"));
        for _ in 0..10 {
            dev.link_mut().pause();
        }
        let (sb, pb) = at(&mut dev);
        let expected = (sb - sa) as i64 * inc;
        assert!(
            (pb - pa - expected).abs() <= 2 * (sb - sa) as i64,
            "over the take ({sa} -> {sb}): {} sub-counts, {expected} expected",
            pb - pa
        );
        let st = ask(&mut dev, "status");
        assert!(
            st.contains("fault_names=none") && st.contains("moving=1"),
            "{st}"
        );
    }
}

/// The divider's code for `volts` on [`board`]'s divider (1:16, 3.3 V at 4095).
fn supply_code(volts: f32) -> u32 {
    (volts / 16.0 / 3.3 * 4095.0).round() as u32
}

/// A current-mode loop on [`board`] handed a measured supply of `volts` (as the
/// protocol side's supervision does), enabled with a current command: its first duty.
fn current_mode_duty(volts: f32) -> f32 {
    let b = board();
    let a = prepare(&default_settings(), &b).unwrap();
    let zero = calibrate_sense(&b, 3.4, || Some(codes(2048)));
    let mut lp = ControlLoop::new(b, a, zero.sense, zero.faults, 0, buffer(), ctrl_buf());
    let mut req = Some(leak(Requests {
        enable: true,
        current: Some(0.05),
        supply_v: Some(volts),
        ..Requests::default()
    }));
    for _ in 0..100 {
        let inp = Inputs {
            encoder: 0,
            // The sense reads zero current: the PI's first output is its proportional part
            // on the same error, whatever the supply.
            current_codes: codes(2048),
            since_last: period_cycles(),
        };
        let o = lp.step(inp, |_, _| req.take());
        lp.finish(1000, false);
        if o.enabled && o.duty != 0.0 {
            assert_eq!(lp.faults(), Faults::NONE);
            return o.duty;
        }
    }
    panic!("never drove");
}

/// The current loop's gain follows the measured supply: the same voltage for the same
/// error is half the duty on 24 V as on 12 V (a 24 V supply under the 12 V setting doubled
/// the loop's gain before).
#[test]
fn the_current_loops_duty_follows_the_measured_supply() {
    let (d12, d24) = (current_mode_duty(12.0), current_mode_duty(24.0));
    assert!(d12 > 0.0, "{d12}");
    assert!(
        (d12 / d24 - 2.0).abs() < 1e-5,
        "{d12} on 12 V, {d24} on 24 V"
    );
}

/// `calls` of the shell's supply supervision 20 ms apart, a PWM period of the loop before
/// each.
fn supervise_every_20_ms(dev: &mut gms_core::device::Front<InlineLink, MemStore>, calls: u32) {
    use gms_core::device::LoopLink as _;
    for _ in 0..calls {
        dev.link_mut().t_us += 20_000;
        dev.link_mut().pause();
        dev.supervise();
    }
}

/// The protocol side measures the supply from the divider's codes (`Front::supervise`):
/// outside the bridge's range `enable` is refused with the reason; a supply that collapses
/// while driving latches `supply` and the bridge goes off; the measured supply is handed to
/// the loop.
#[test]
fn a_supply_outside_the_bridges_range_refuses_enable_and_latches_while_driving() {
    let mut dev = board_device_on(board(), None);
    dev.link_mut().supply = Some(supply_code(5.0));
    assert_eq!(
        ask(&mut dev, "enable").trim(),
        "err 8 motor supply below the bridge's range"
    );
    dev.link_mut().supply = Some(supply_code(50.0));
    // The filter (0.2 s) follows over a second of the calls' time.
    supervise_every_20_ms(&mut dev, 50);
    assert_eq!(
        ask(&mut dev, "enable").trim(),
        "err 8 motor supply above the bridge's range"
    );
    dev.link_mut().supply = Some(supply_code(12.0));
    // From 50 V: (1 - 0.1)^100 of the 38 V step left, 1 mV.
    supervise_every_20_ms(&mut dev, 100);
    let v = dev.supply_v().unwrap();
    assert!((v - 12.0).abs() < 0.05, "{v}");
    assert!(ask(&mut dev, "enable").starts_with("ok"));
    // The supply collapses to 3 V while driving: latched within the filter's time.
    dev.link_mut().supply = Some(supply_code(3.0));
    let mut calls = 0;
    while !ask(&mut dev, "status").contains("fault_names=supply") {
        supervise_every_20_ms(&mut dev, 1);
        calls += 1;
        assert!(calls < 100, "never latched");
    }
    // From 12 V through 6.5 V toward 3 V with a 0.2 s filter, at 20 ms a call:
    // (1 - 0.1)^n = 3.5 / 9, n = 9 calls.
    assert!((8..=11).contains(&calls), "{calls} calls");
    assert!(ask(&mut dev, "status").contains("enabled=0"));
}

/// `status` says the supply the current loop works for: the measured one where the board has
/// a divider, `lim.v_supply` where it has none.
#[test]
fn the_status_states_the_supply() {
    use gms_core::device::LoopLink as _;
    let field = |st: &str| -> f32 {
        let w = st
            .split_whitespace()
            .find(|w| w.starts_with("supply="))
            .unwrap();
        w["supply=".len()..].parse().unwrap()
    };
    let mut dev = board_device_on(board(), None);
    dev.link_mut().supply = Some(supply_code(24.0));
    dev.link_mut().pause();
    dev.supervise();
    // The code's own step: 24 V reads code 1862, 23.998 V.
    let v = field(&ask(&mut dev, "status"));
    assert!((v - 24.0).abs() < 0.013, "{v}");
    let mut dev = board_device_on(no_divider_board(), None);
    assert!(ask(&mut dev, "set lim.v_supply 36").starts_with("ok"));
    assert_eq!(field(&ask(&mut dev, "status")), 36.0);
}

/// The F405 board without its supply divider.
fn no_divider_board() -> Board {
    Board {
        supply: None,
        ..board()
    }
}

/// A board that does not measure its supply drives only once `lim.v_supply` is confirmed:
/// refused on the built-in defaults (with the reason), driving after a `set` of it (to the
/// same value too), refused again after `defaults`; a `commit` that changes it confirms it,
/// and so does a stored set.
#[test]
fn a_board_without_a_divider_drives_only_once_its_supply_is_confirmed() {
    let why = "err 8 this board does not measure its motor supply: set lim.v_supply first";
    let mut dev = board_device_on(no_divider_board(), None);
    assert_eq!(ask(&mut dev, "enable").trim(), why);
    assert_eq!(ask(&mut dev, "enable current").trim(), why);
    // Another parameter does not confirm it.
    assert!(ask(&mut dev, "set pos.kp 0.5").starts_with("ok"));
    assert_eq!(ask(&mut dev, "enable").trim(), why);
    // The same value, set: confirmed.
    assert!(ask(&mut dev, "set lim.v_supply 12").starts_with("ok"));
    assert!(ask(&mut dev, "enable").starts_with("ok"));
    assert!(ask(&mut dev, "disable").starts_with("ok"));
    assert!(ask(&mut dev, "defaults").starts_with("ok"));
    assert_eq!(ask(&mut dev, "enable").trim(), why);
    // A staged change, committed.
    assert!(ask(&mut dev, "stage lim.v_supply 24").starts_with("ok"));
    assert!(ask(&mut dev, "commit").starts_with("ok"));
    assert!(ask(&mut dev, "enable").starts_with("ok"));
    assert!(ask(&mut dev, "disable").starts_with("ok"));
    // Saved, the board powers up on the stored set: confirmed.
    assert!(ask(&mut dev, "save").starts_with("ok"));
    let stored = dev.into_parts().1.0;
    let mut dev = board_device_on(no_divider_board(), stored);
    assert!(ask(&mut dev, "enable").starts_with("ok"));
}

/// A measured supply survives a parameter hand-over, even one equal to the old set's
/// `lim.v_supply` while the new set's differs: the current loop keeps dividing by what the
/// board measured, not by the new nominal.
#[test]
fn a_measured_supply_survives_a_hand_over_whatever_the_nominal() {
    use gms_core::control::controller::Controller;
    let s = default_settings();
    let mut a: Controller<6> = Controller::try_new(s).unwrap();
    a.set_measured_supply(Some(s.v_supply));
    let mut s24 = s;
    s24.v_supply = 2.0 * s.v_supply;
    let mut b: Controller<6> = Controller::try_new(s24).unwrap();
    assert_eq!(b.supply(), 2.0 * s.v_supply);
    b.take_state_from(&a);
    assert_eq!(b.supply(), s.v_supply);
    // Not measured: the new set's nominal.
    let c: Controller<6> = Controller::try_new(s).unwrap();
    let mut d: Controller<6> = Controller::try_new(s24).unwrap();
    d.take_state_from(&c);
    assert_eq!(d.supply(), 2.0 * s.v_supply);
}
