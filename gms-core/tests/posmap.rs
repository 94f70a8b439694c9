//! The position map's cursor: the interpolated table at the reference, against the table's
//! own line between bins; the phase kept by increments agrees with a division at every step,
//! across wraps, jumps and either direction.

use gms_core::control::posmap::{MAP_VALUES, MapCursor, MapParams};
use gms_core::control::reference::SUB_PER_COUNT;

#[test]
fn the_cursor_interpolates_the_table_at_the_reference() {
    let rpc = 1e-3f32; // a coarse encoder: 6283.2 counts a revolution
    let m = MapParams {
        enable: 1.0,
        period: std::f32::consts::TAU,
        bins: 64.0,
        origin: 0.5,
    };
    // Offset = the bin's index, scale = 1 + index / 100.
    let mut table = [0.0f32; MAP_VALUES];
    for k in 0..64 {
        table[2 * k] = k as f32;
        table[2 * k + 1] = 1.0 + k as f32 / 100.0;
    }
    let sub = SUB_PER_COUNT as f64;
    let period_sub = (m.period as f64 / rpc as f64 * sub) as i64;
    let origin_sub = (m.origin as f64 / rpc as f64 * sub) as i64;
    let expect = |r: i64| -> (f64, f64) {
        let p = (r - origin_sub).rem_euclid(period_sub) as f64;
        let u = p * 64.0 / period_sub as f64;
        let i = u.floor();
        let f = u - i;
        let j = (i + 1.0) % 64.0;
        let o = i + f * (j - i);
        (o, 1.0 + o / 100.0)
    };
    let mut c = MapCursor::new(&m, rpc, 0);
    let mut r: i64 = 0;
    let mut worst: f64 = 0.0;
    // Steps of a few counts either way, a jump of several periods, then back.
    let steps: Vec<i64> = (0..20_000)
        .map(|k| match k {
            5000 => 3 * period_sub + 12345,
            12_000 => -7 * period_sub,
            _ if k < 9000 => 3 * 65536 + 17,
            _ => -(5 * 65536 + 3),
        })
        .collect();
    for d in steps {
        r += d;
        let (o, s) = c.sample(r, &table);
        let (eo, es) = expect(r);
        // Between bins 63 and 0 the line runs from 63 down to 0: the fraction's error is
        // what f32 keeps of the phase (~1e-7 of the period).
        worst = worst
            .max((o as f64 - eo).abs())
            .max((s as f64 - es).abs() * 100.0);
    }
    assert!(worst < 2e-3, "worst {worst}");
    // Without a table (or a short one) the map is neutral.
    assert_eq!(c.sample(r + 1, &[]), (0.0, 1.0));
}
