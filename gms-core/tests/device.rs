//! The device core's control loop on its own: missed periods.

use gms_core::device::{
    Board, ControlLoop, Inputs, Requests, SenseChain, calibrate_sense, default_settings, prepare,
};
use gms_core::drive::{BoardLimits, Faults};

fn board() -> Board {
    Board {
        pwm_timer_hz: 168_000_000,
        pwm_max_arr: 65_534,
        encoder_bits: 32,
        sense_oversample: 16,
        sense: SenseChain {
            amps_per_code: 2.37e-4,
            zero_code: 2048.0,
            zero_tolerance: 150.0,
            window_s: 0.0,
        },
        limits: BoardLimits {
            trip_factor: 1.5,
            sense_range: 0.48,
            max_error: 0.01,
            max_speed: 100.0,
            clock_hz: 168_000_000,
            budget_fraction: 0.6,
        },
        has_truth: false,
        bridge_wake_s: 0.0,
        capture_values: 8192,
    }
}

/// A capture buffer for a test's loop.
fn buffer() -> &'static mut [f32] {
    Box::leak(vec![0.0; 8192].into_boxed_slice())
}

/// A loop at rest at count 0, zero current.
fn rest() -> ControlLoop {
    let b = board();
    let a = prepare(&default_settings(), &b).unwrap();
    let zero = calibrate_sense(&b, || 16 * 2048);
    ControlLoop::new(b, a, zero.sense, zero.faults, 0, buffer())
}

fn step(lp: &mut ControlLoop, since_last: u32, req: Option<Requests>) {
    let mut req = req;
    let inp = Inputs {
        encoder: 0,
        current_codes: 16 * 2048,
        since_last,
    };
    lp.step(inp, |_, _| req.take());
    lp.finish(1000);
}

#[test]
fn a_missed_period_is_counted_and_latches_overrun_while_driving() {
    let period = 168_000_000 / 20_000;
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

#[test]
fn after_enable_the_bridge_wakes_in_brake_before_control() {
    let mut b = board();
    b.bridge_wake_s = 1e-3;
    let a = prepare(&default_settings(), &b).unwrap();
    let zero = calibrate_sense(&b, || 16 * 2048);
    let mut lp = ControlLoop::new(b, a, zero.sense, zero.faults, 0, buffer());
    let period = 168_000_000 / 20_000;
    let mut req = Some(Requests {
        enable: true,
        ..Requests::default()
    });
    // The axis reads 5 counts off its hold point: control would drive at once.
    let mut outs = Vec::new();
    for _ in 0..40 {
        let inp = Inputs {
            encoder: if outs.is_empty() { 0 } else { 5 },
            current_codes: 16 * 2048,
            since_last: period,
        };
        let o = lp.step(inp, |_, _| req.take());
        lp.finish(1000);
        outs.push(o);
    }
    let arr = lp.timing().1;
    // 1 ms at 20 kHz: 20 periods of brake (both inputs high for the whole period, but for
    // the single count at the top on the PWM side), duty 0.
    for (k, o) in outs.iter().enumerate().take(20) {
        assert!(o.enabled, "{k}");
        assert_eq!(o.duty, 0.0, "{k}");
        assert!(
            o.compare.0 >= arr && o.compare.1 >= arr,
            "{k}: {:?}",
            o.compare
        );
    }
    // Then the loop controls: the 5-count error gives a duty.
    assert!(outs[20..].iter().any(|o| o.duty != 0.0));
    assert_eq!(lp.faults(), Faults::NONE);
}

#[test]
fn capture_field_lists() {
    use gms_core::device::capture_fields;
    assert_eq!(capture_fields("t,pos,current"), Ok(([0, 1, 5, 0], 3)));
    assert_eq!(capture_fields("friction"), Ok(([6, 0, 0, 0], 1)));
    assert_eq!(capture_fields("t,ref,error,ff"), Ok(([0, 2, 3, 4], 4)));
    for bad in ["", "t,", ",t", "t,,pos", "speed", "t,pos,ref,error,ff", "T"] {
        assert!(capture_fields(bad).is_err(), "{bad:?}");
    }
}

#[test]
fn a_capture_records_what_the_loop_saw() {
    use gms_core::device::{CaptureRequest, CaptureSpec, CaptureState};
    let period = 168_000_000 / 20_000;
    let mut lp = rest();
    // Every 2nd position step, pos and current, 10 samples, at once.
    let spec = CaptureSpec {
        fields: [1, 5, 0, 0],
        nfields: 2,
        every: 2,
        samples: 10,
        on_next: false,
    };
    step(
        &mut lp,
        period,
        Some(Requests {
            capture: Some(CaptureRequest::Arm(spec)),
            ..Requests::default()
        }),
    );
    for _ in 0..60 {
        step(&mut lp, period, None);
    }
    let st = lp.status();
    assert_eq!((st.capture, st.captured), (CaptureState::Done, 10));
    // Read back through the mailbox's chunk: position 0 (at rest), current 0.
    let mut chunk = None;
    let mut req = Some(Requests {
        capture: Some(CaptureRequest::Read { start: 0, max: 64 }),
        ..Requests::default()
    });
    for _ in 0..4 {
        let inp = Inputs {
            encoder: 0,
            current_codes: 16 * 2048,
            since_last: period,
        };
        lp.step(inp, |_, c| {
            if let Some(c) = c {
                chunk = Some(*c);
            }
            req.take()
        });
    }
    let c = chunk.expect("a chunk");
    assert_eq!((c.start, c.samples, c.nfields), (0, 10, 2));
    assert!(c.values[..20].iter().all(|v| *v == 0.0));
}

/// `current AMPS SECONDS`: the current held for so many position steps, then 0 A, still in
/// current mode (a pulse the device ends whatever the link does).
#[test]
fn a_timed_current_ends_on_the_device() {
    let mut lp = rest();
    let period = 168_000_000 / 20_000;
    step(
        &mut lp,
        period,
        Some(Requests {
            enable: true,
            current: Some(0.0),
            ..Requests::default()
        }),
    );
    // (Requests are taken at a position step: every other call.)
    step(&mut lp, period, None);
    // 0.1 A for 25 position steps (2.5 ms at 10 kHz; two PWM periods per step).
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
    // Two PWM periods (calls) per position step: 25 steps are 50 calls at 0.1 A.
    let on = held.iter().filter(|a| **a == 0.1).count();
    assert!((48..=52).contains(&on), "{on} periods at 0.1 A: {held:?}");
    assert!(held[60..].iter().all(|a| *a == 0.0), "{held:?}");
    assert!(lp.enabled());
}

/// A `save` holds the CPU for up to 2 s (a flash erase): the first step after it sees the
/// whole motion of that time as one increment. Checked against the periods that really
/// elapsed, an axis that drifted at a legal 50 rad/s (half the board's 100 rad/s) is no
/// encoder jump; one that moved faster than the board allows over that time still is.
#[test]
fn an_encoder_increment_is_checked_against_the_periods_that_elapsed() {
    let period = 168_000_000 / 20_000;
    let rpc = default_settings().rad_per_count as f64;
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
                current_codes: 16 * 2048,
                since_last: if k == 0 {
                    (stall_s * 168e6) as u32
                } else {
                    period
                },
            };
            lp.step(inp, |_, _| None);
            lp.finish(1000);
        }
        assert_eq!(
            lp.faults().contains(Faults::ENCODER_JUMP),
            jump,
            "{speed} rad/s: {:?}",
            lp.faults()
        );
    }
}
