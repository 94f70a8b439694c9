//! The point-to-point reference of the devices (`move`): plays the move, then holds where it
//! ended; `hold_at` and `stop` as the firmware and the simulated device use them.

use gms_core::reference::{MOVE_VMAX, Motion, SUB_PER_COUNT};

#[test]
fn a_move_ends_at_its_target_and_holds_there() {
    let rpc = 3.8e-6f32;
    let start = 1_000 * SUB_PER_COUNT as i64;
    let mut m = Motion::holding(start);
    let r = Motion::plan(start, 0.01, None, rpc).unwrap();
    m.start(r);
    assert!(m.is_moving());
    let dt = 1e-4;
    let mut peak = 0.0f32;
    let mut n = 0;
    while m.is_moving() && n < 100_000 {
        peak = peak.max(m.next(dt).vel.abs());
        n += 1;
    }
    assert!(!m.is_moving(), "the move never finished");
    // `move` takes an absolute position: 0.01 rad = 2631.6 counts, within the f32 rounding
    // of the distance (6e-8 relative: a thousandth of a count here).
    let target = 0.01 / rpc as f64 * SUB_PER_COUNT as f64;
    let tol = 1e-3 * SUB_PER_COUNT as f64;
    assert!(
        (m.hold() as f64 - target).abs() <= tol,
        "{} vs {target}",
        m.hold()
    );
    assert!(peak <= MOVE_VMAX * 1.0001 && peak > 0.0, "{peak}");
    let held = m.next(dt);
    assert_eq!((held.pos, held.vel, held.acc), (m.hold(), 0.0, 0.0));
}

#[test]
fn stop_keeps_the_hold_and_hold_at_moves_it() {
    let mut m = Motion::holding(5);
    m.start(Motion::plan(5, 1.0, Some(0.2), 1e-3).unwrap());
    m.next(1e-3);
    m.next(1e-3);
    m.stop();
    assert!(!m.is_moving());
    assert_eq!(m.next(1e-3).pos, 5);
    m.hold_at(77);
    assert_eq!(m.next(1e-3).pos, 77);
    // A bad speed is refused, not played.
    assert!(Motion::plan(5, 1.0, Some(-1.0), 1e-3).is_err());
}
