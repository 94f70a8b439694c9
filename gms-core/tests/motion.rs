//! The point-to-point reference of the devices (`move`): plays the move, then holds where it
//! ended; a new move planned from the reference of a move under way continues it without a
//! jump; `hold_at` and `stop` as the device core uses them.

use gms_core::control::reference::{
    MOVE_AMAX, MOVE_JMAX, MOVE_VMAX, Motion, RefSample, Reference, SUB_PER_COUNT, Segment,
};

const RPC: f32 = 3.8e-6;
const DT: f32 = 1e-4;

fn at_rest(pos: i64) -> RefSample {
    RefSample {
        pos,
        vel: 0.0,
        acc: 0.0,
    }
}

/// Plays `m` to the end; returns the samples.
fn play(m: &mut Motion) -> Vec<RefSample> {
    let mut out = Vec::new();
    while m.is_moving() && out.len() < 1_000_000 {
        out.push(m.next(DT));
    }
    assert!(!m.is_moving(), "the move never finished");
    out
}

/// Velocity and acceleration continuity and the limits over a played reference: every change
/// of velocity within `amax dt`, of acceleration within `jmax dt` (1 % and a little f32 slack),
/// and the position increments agreeing with the velocity.
fn assert_smooth(s: &[RefSample], vmax: f32) {
    for w in s.windows(2) {
        let (a, b) = (w[0], w[1]);
        assert!(b.vel.abs() <= vmax * 1.0001, "speed {} above {vmax}", b.vel);
        assert!(b.acc.abs() <= MOVE_AMAX * 1.001, "acc {}", b.acc);
        assert!(
            (b.vel - a.vel).abs() <= MOVE_AMAX * DT * 1.01 + 1e-6,
            "velocity jump {} -> {}",
            a.vel,
            b.vel
        );
        assert!(
            (b.acc - a.acc).abs() <= MOVE_JMAX * DT * 1.011 + 1e-3,
            "acceleration jump {} -> {}",
            a.acc,
            b.acc
        );
        // Position increment against the mean velocity (trapezoid), in counts.
        let dx = (b.pos - a.pos) as f64 / SUB_PER_COUNT as f64;
        let expect = 0.5 * (a.vel + b.vel) as f64 * DT as f64 / RPC as f64;
        assert!(
            (dx - expect).abs() <= 0.05 + 1e-3 * expect.abs(),
            "position jump {dx} counts where the velocity says {expect}"
        );
    }
}

#[test]
fn a_move_ends_at_its_target_and_holds_there() {
    let start = 1_000 * SUB_PER_COUNT as i64;
    let mut m = Motion::holding(start);
    m.start(Motion::plan(at_rest(start), 0.01, None, RPC).unwrap());
    assert!(m.is_moving());
    let s = play(&mut m);
    // `move` takes an absolute position: 0.01 rad = 2631.6 counts.
    let target = 0.01 / RPC as f64 * SUB_PER_COUNT as f64;
    let tol = 1e-3 * SUB_PER_COUNT as f64;
    assert!(
        (m.hold() as f64 - target).abs() <= tol,
        "{} vs {target}",
        m.hold()
    );
    let peak = s.iter().map(|r| r.vel.abs()).fold(0.0, f32::max);
    // Jerk-limited at this distance (0.01 rad - 1000 counts): T = cbrt(60 D / jmax), peak
    // 1.875 D / T.
    let d = 0.01 - 1000.0 * RPC as f64;
    let t = (60.0 * d / MOVE_JMAX as f64).cbrt();
    let expect = (1.875 * d / t) as f32;
    assert!((peak - expect).abs() < 1e-3 * expect, "{peak} vs {expect}");
    assert_smooth(&s, MOVE_VMAX);
    let held = m.next(DT);
    assert_eq!((held.pos, held.vel, held.acc), (m.hold(), 0.0, 0.0));
}

#[test]
fn from_rest_it_is_the_minimum_jerk_segment() {
    // The other implementation: gms-core's Segment::Move (the scenarios' moves).
    let start = -77 * SUB_PER_COUNT as i64;
    let seg = Segment::Move {
        distance: 0.004 + 77.0 * RPC,
        vmax: 0.2,
        amax: MOVE_AMAX,
        jmax: MOVE_JMAX,
        dwell: 1e-3,
    };
    let mut r = Reference::<1>::try_new(&[seg], RPC, start).unwrap();
    let mut m = Motion::holding(start);
    m.start(Motion::plan(at_rest(start), 0.004, Some(0.2), RPC).unwrap());
    let s = play(&mut m);
    for (k, a) in s.iter().enumerate() {
        let b = r.next(DT);
        let dpos = (a.pos - b.pos).abs() as f64 / SUB_PER_COUNT as f64;
        assert!(dpos < 0.01, "step {k}: {dpos} counts apart");
        assert!(
            (a.vel - b.vel).abs() < 1e-5 * 0.2,
            "step {k}: {} vs {}",
            a.vel,
            b.vel
        );
    }
}

#[test]
fn a_second_move_mid_move_continues_it() {
    let mut m = Motion::holding(0);
    m.start(Motion::plan(at_rest(0), 0.01, None, RPC).unwrap());
    let mut s: Vec<RefSample> = (0..150).map(|_| m.next(DT)).collect();
    let last = *s.last().unwrap();
    assert!(last.vel > 0.1 && last.acc.abs() > 1.0, "mid-move: {last:?}");
    // Further on, planned from the last sample (as the device core does).
    let mut plan = Motion::plan(last, 0.02, None, RPC).unwrap();
    plan.skip(DT);
    m.start(plan);
    s.extend(play(&mut m));
    assert_smooth(&s, MOVE_VMAX);
    // Never backs up (beyond the f32 rounding of the polynomial near the end, where it meets
    // the exact target: below 1/100 count).
    for (k, w) in s.windows(2).enumerate() {
        assert!(
            w[1].pos >= w[0].pos - 656,
            "backs up at {k} of {}: {:?} -> {:?}",
            s.len(),
            w[0],
            w[1]
        );
    }
    let target = 0.02 / RPC as f64 * SUB_PER_COUNT as f64;
    assert!((m.hold() as f64 - target).abs() <= 1e-3 * SUB_PER_COUNT as f64);
}

#[test]
fn a_move_back_mid_move_turns_smoothly() {
    let mut m = Motion::holding(0);
    m.start(Motion::plan(at_rest(0), 0.01, None, RPC).unwrap());
    let mut s: Vec<RefSample> = (0..150).map(|_| m.next(DT)).collect();
    let last = *s.last().unwrap();
    let mut plan = Motion::plan(last, -0.002, Some(0.3), RPC).unwrap();
    plan.skip(DT);
    m.start(plan);
    s.extend(play(&mut m));
    // The speed at the turn was above 0.3: the plan may keep the start's own speed, and the
    // acceleration it had goes to zero at the jerk limit first (+ a0^2 / 2 jmax).
    let v1 = last.vel.abs() + last.acc * last.acc / (2.0 * MOVE_JMAX);
    assert_smooth(&s, v1.max(0.3));
    let target = -0.002 / RPC as f64 * SUB_PER_COUNT as f64;
    assert!((m.hold() as f64 - target).abs() <= 1e-3 * SUB_PER_COUNT as f64);
    let turned = s.iter().map(|r| r.pos).max().unwrap();
    assert!(turned > last.pos, "it turns after going on a little");
}

#[test]
fn stop_holds_where_the_reference_was_and_hold_at_moves_it() {
    let mut m = Motion::holding(5);
    m.start(Motion::plan(at_rest(5), 1.0, Some(0.2), 1e-3).unwrap());
    m.next(1e-3);
    let r = m.next(1e-3);
    m.stop();
    assert!(!m.is_moving());
    assert_eq!(m.next(1e-3).pos, r.pos);
    m.hold_at(77);
    assert_eq!(m.next(1e-3).pos, 77);
    // A bad speed is refused, not played.
    assert!(Motion::plan(at_rest(5), 1.0, Some(-1.0), 1e-3).is_err());
    assert!(Motion::plan(at_rest(5), f32::NAN, None, 1e-3).is_err());
}

#[test]
fn a_velocity_profile_ramps_holds_and_sweeps() {
    use gms_core::control::reference::{RefSample, SUB_PER_COUNT, Sweep, VelocityProfile};
    let rpc = 3.8e-6f32;
    let dt = 1e-4f32;
    // From rest at count 1000 to 0.5 rad/s at 50 rad/s²: 10 ms of ramp.
    let from = RefSample {
        pos: 1000 * SUB_PER_COUNT as i64,
        vel: 0.0,
        acc: 0.0,
    };
    let sweep = Sweep {
        amp: 0.2,
        f0: 2.0,
        f1: 10.0,
        seconds: 1.0,
    };
    let mut p = VelocityProfile::new(from, 0.5, Some(sweep), 50.0, rpc).unwrap();
    let mut prev = from;
    let mut integral = 0.0f64;
    let mut max_dv = 0.0f32;
    let mut samples = Vec::new();
    for k in 0..15_000 {
        let r = p.next(dt);
        let dv = (r.vel - prev.vel).abs();
        if !(100..10_100).contains(&k) {
            // The ramps, up and (after the sweep) down to rest: no speed change beyond
            // amax·dt.
            assert!(dv <= 50.0 * dt * 1.0001, "step {k}: dv {dv}");
        } else {
            max_dv = max_dv.max(dv);
        }
        integral += 0.5 * (prev.vel + r.vel) as f64 * dt as f64;
        // The position is the speed's integral, to a sub-count.
        let pos_rad = (r.pos - from.pos) as f64 / SUB_PER_COUNT as f64 * rpc as f64;
        assert!((pos_rad - integral).abs() < 2.0 * rpc as f64 / SUB_PER_COUNT as f64 + 1e-12);
        samples.push(r.vel);
        prev = r;
    }
    // Ramp done after 100 steps (0.5 / 50 = 10 ms); the sweep then stays within mean ± amp,
    // reaches both extremes, is continuous (no step above amp·2π·f1·dt), and ends: the speed
    // ramps from the mean to rest (another 100 steps) and stays there (a run that ends on the
    // device).
    assert!((samples[99] - 0.5).abs() < 1e-6);
    let sweep_part = &samples[100..10_100];
    let (lo, hi) = sweep_part
        .iter()
        .fold((f32::MAX, f32::MIN), |(l, h), v| (l.min(*v), h.max(*v)));
    assert!(lo > 0.3 - 1e-4 && lo < 0.31, "{lo}");
    assert!(hi < 0.7 + 1e-4 && hi > 0.69, "{hi}");
    assert!(
        max_dv <= 0.2 * std::f32::consts::TAU * 10.0 * dt * 1.01 + 1e-6,
        "{max_dv}"
    );
    assert!((samples[10_100] - 0.5).abs() < 1e-6, "{}", samples[10_100]);
    assert!(samples[10_100..10_201].windows(2).all(|w| w[1] <= w[0]));
    assert!(samples[10_201..].iter().all(|v| *v == 0.0));
    // Zero crossings of (v - mean) in the sweep: the frequency rises from 2 to 10 Hz, so
    // the mean frequency is 6 Hz: 2 × 6 crossings in the 1 s.
    let crossings = sweep_part
        .windows(2)
        .filter(|w| (w[0] - 0.5).signum() != (w[1] - 0.5).signum())
        .count();
    assert!((11..=13).contains(&crossings), "{crossings}");
    // Refused: too fast, nonsense sweep figures, non-finite values.
    let bad = |vel: f32, s: Option<Sweep>| VelocityProfile::new(from, vel, s, 50.0, rpc).is_err();
    assert!(bad(25.0, None));
    assert!(bad(19.9, Some(Sweep { amp: 0.2, ..sweep })));
    assert!(bad(0.5, Some(Sweep { f0: 0.0, ..sweep })));
    assert!(bad(
        0.5,
        Some(Sweep {
            seconds: -1.0,
            ..sweep
        })
    ));
    assert!(bad(f32::NAN, None));
    assert!(!bad(-0.5, None));
}
