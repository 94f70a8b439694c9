//! One control-loop schedule: `hil-sim`'s closed-loop runs (`run`, `compare`, `demo`: the
//! README's figures) step the controller through `hil_sim::sim::Schedule`; the board and the
//! virtual device run the device core's `ControlLoop`. Fed the same encoder counts and the same
//! current-sense codes period by period, along a move, the two give the same duty in every
//! PWM period, bit for bit: the runs' figures are the device core's control.

use gms_core::control::reference::{Motion, SUB_PER_COUNT};
use gms_core::device::{
    self, Board, ControlLoop, Inputs, MoveRequest, Requests, calibrate_sense, default_settings,
};
use hil_sim::sim::Schedule;

#[test]
fn the_run_schedule_is_the_device_core_s_duty_for_duty() {
    let board = Board {
        bridge_wake_s: 0.0,
        ..gms_core::boards::f405::BOARD
    };
    let s = default_settings();
    let applied = device::prepare(&s, &board).unwrap();
    let mut shadow = Schedule::new(applied.ctrl.clone());
    // The board's conversions per current sample.
    let n = board.sense_oversample;
    let zero = calibrate_sense(&board, s.sense_v_per_a, || Some(n * 2048));
    let sense = zero.sense;
    let buf: &'static mut [f32] = Box::leak(vec![0.0; 8192].into_boxed_slice());
    let ctrl = Box::leak(Box::new(applied.ctrl.clone()));
    let mut lp = ControlLoop::new(board, applied, zero.sense, zero.faults, 0, buf, ctrl);
    let ratio = lp.ratio();
    let rpc = s.rad_per_count();
    // A plant stand-in: the axis follows the reference with a lag and a wobble of a few
    // counts, the current wanders over ±0.1 A (codes around the zero).
    let mut count: i64 = 0;
    // Taken last first: the enable, then the move.
    let mut pending = vec![
        Requests::default(),
        Requests {
            enable: true,
            ..Requests::default()
        },
    ];
    let mut compared = 0;
    // 2 s of the current loop's periods.
    let periods = (2.0 * s.cur_rate_hz) as u32;
    for k in 0..periods {
        let codes = n * 2048 + ((k.wrapping_mul(2_654_435_761) >> 20) % (n * 60));
        let codes = codes - n * 30;
        let inp = Inputs {
            encoder: count as u32,
            current_codes: codes,
            since_last: (168e6 / s.cur_rate_hz) as u32,
        };
        let phase0 = k % ratio == 0;
        // (The loop asks for requests once a position period, in its last current step.)
        let out = lp.step(inp, |st, _| {
            let st = st();
            let mut r = pending.pop();
            if let Some(req) = &mut r
                && !req.enable
            {
                // The move, planned from the reference as the front plans it: 0.3 rad at up
                // to 0.4 rad/s and back.
                let plan = Motion::plan(st.reference, 0.3, Some(0.4), rpc).unwrap();
                req.motion = Some(MoveRequest {
                    plan,
                    from_step: st.steps,
                });
            }
            // In storage of their own: the loop takes requests by reference.
            r.map(|r| &mut *Box::leak(Box::new(r)))
        });
        assert!(
            out.enabled || k + 1 < ratio as u32,
            "the loop went off at period {k}: {:?}",
            lp.faults()
        );
        if k + 1 == ratio as u32 {
            // The enable (taken in the position period's last current step) resets the
            // loop's controller where the axis is: the same for the shadow.
            shadow.controller().reset();
        }
        // The shadow steps in every period, so that its position steps fall in the loop's.
        let st = lp.status();
        let amps = s.sense_dir * sense.amps_sum(codes, n);
        let (duty, _) = shadow.period(st.pos, &st.reference, amps);
        if !out.enabled {
            continue;
        }
        assert_eq!(
            duty.to_bits(),
            out.duty.to_bits(),
            "period {k}: the schedule's duty {duty}, the device core's {}",
            out.duty
        );
        compared += 1;
        lp.finish(1000, false);
        // The axis: the reference's count less a lag and a wobble.
        if phase0 {
            let target = st.reference.pos / SUB_PER_COUNT as i64;
            count = target - 3 + (k as i64 / ratio as i64 % 7);
        }
    }
    assert!(compared > periods - periods / 40, "{compared}");
    // The move really went somewhere: 0.3 rad of counts.
    let reached = lp.status().pos as f64 * rpc as f64;
    assert!((reached - 0.3).abs() < 1e-3, "{reached}");
}
