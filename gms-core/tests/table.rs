//! The table motion (`gms_core::control::table`): the reference between its points, the error's bins
//! and figures, the correction's swap at a period's start, the run's end, and the checks of a
//! table as it is written — each against an independent expectation.

use gms_core::control::table::{
    Geometry, Player, Recorded, TABLE_POINTS, TABLE_VALUES, TableError, TableRequest, TableState,
    Upload, Which,
};
use gms_core::device::Chunk;

const RATE: f32 = 10_000.0;
const RPC: f32 = 3.8e-6;

fn chunk() -> Chunk {
    Chunk::new(0, 1)
}

/// Writes `values` into the table `which` in blocks of eight, as the protocol side does.
fn write(p: &mut Player, t: &mut [f32], which: Which, values: &[f32]) {
    for (i, block) in values.chunks(8).enumerate() {
        let mut v = [0.0; 8];
        v[..block.len()].copy_from_slice(block);
        let w = TableRequest::Write {
            which,
            start: (i * 8) as u32,
            n: block.len() as u32,
            values: v,
        };
        p.take(&w, t, None);
    }
}

/// A player with the reference `values` set (`steps` apart, origin `origin`).
fn player(values: &[f32], steps: u32, origin: i64) -> (Player, Vec<f32>) {
    let mut t = vec![0.0f32; TABLE_VALUES];
    let mut p = Player::default();
    write(&mut p, &mut t, Which::Ref, values);
    let g = Geometry {
        points: values.len() as u32,
        steps,
        origin,
    };
    p.take(&TableRequest::Set(g), &mut t, None);
    (p, t)
}

/// Writes a correction and has it played.
fn write_corr(p: &mut Player, t: &mut [f32], values: &[f32]) {
    write(p, t, Which::Corr, values);
    p.take(&TableRequest::Use, t, None);
}

/// A sine's table: between its points the reference is the periodic cubic through them — at
/// the points exactly, and between them within 1e-3 count of the sine, its velocity within
/// 0.05 % of the sine's peak velocity and its acceleration within 3 % of the peak (the
/// cubic's second derivative is linear between points and jumps at them: 2.1 % at 1000
/// points a period; the acceleration only feeds `J a`).
#[test]
fn the_reference_between_points_follows_the_path() {
    let n = 1000usize;
    let steps = 10u32;
    let a = 13_158.0f64; // counts: 0.05 rad
    let w = std::f64::consts::TAU / n as f64;
    let values: Vec<f32> = (0..n)
        .map(|k| (a * (1.0 - (w * k as f64).cos())) as f32)
        .collect();
    let origin = 1_000_000i64;
    let (mut p, mut t) = player(&values, steps, origin);
    let mut c = chunk();
    p.take(&TableRequest::Run(1), &mut t, Some(&mut c));
    p.set_started(0, RPC, RATE);
    assert_eq!(p.report().state, TableState::Playing);
    let per_step = w / f64::from(steps);
    let dt = 1.0 / f64::from(RATE);
    let (mut worst_x, mut worst_v, mut worst_a) = (0.0f64, 0.0f64, 0.0f64);
    for i in 0..n * steps as usize {
        let s = p.sample(&t);
        let th = per_step * i as f64;
        let x = a * (1.0 - th.cos());
        let v = a * th.sin() * per_step / dt * f64::from(RPC);
        let acc = a * th.cos() * (per_step / dt).powi(2) * f64::from(RPC);
        let got = (s.r.pos as f64) / 65536.0 - origin as f64;
        if i % steps as usize == 0 {
            assert!(
                (got - f64::from(values[i / steps as usize])).abs() < 1e-3,
                "{i}"
            );
        }
        worst_x = worst_x.max((got - x).abs());
        worst_v = worst_v.max((f64::from(s.r.vel) - v).abs());
        worst_a = worst_a.max((f64::from(s.r.acc) - acc).abs());
        p.record(&mut t, 0.0);
    }
    let v_peak = a * per_step / dt * f64::from(RPC);
    let a_peak = a * (per_step / dt).powi(2) * f64::from(RPC);
    assert!(worst_x < 2e-3, "position {worst_x} counts");
    assert!(worst_v < 5e-4 * v_peak, "velocity {worst_v} of {v_peak}");
    assert!(
        worst_a < 0.03 * a_peak,
        "acceleration {worst_a} of {a_peak}"
    );
}

/// The error's bins are the means over their steps, the period's RMS and peak those of every
/// step; the buffers swap at the period's end; a correction swaps in at the next period's
/// start, never within one; the run ends after its periods at the table's start.
#[test]
fn periods_bins_and_the_correction_swap() {
    let n = 16usize;
    let steps = 5u32;
    let values: Vec<f32> = (0..n).map(|k| (k as f32 * 0.3).sin() * 4.0).collect();
    let origin = -42i64;
    let (mut p, mut t) = player(&values, steps, origin);
    let mut c = chunk();
    // A correction before the run plays from its start.
    let corr1: Vec<f32> = (0..n).map(|k| 1e-6 * k as f32).collect();
    write_corr(&mut p, &mut t, &corr1);
    assert_eq!(p.report().generation, 1);
    p.take(&TableRequest::Run(3), &mut t, Some(&mut c));
    p.set_started(0, RPC, RATE);
    let err = |period: usize, i: usize| ((period * 1000 + i * 7) % 13) as f32 - 6.0;
    let period_steps = n * steps as usize;
    let mut ends = Vec::new();
    for period in 0..3 {
        if period == 1 {
            // Written and asked for within period 1 (after its first step): played from
            // period 2 only.
            let corr2: Vec<f32> = (0..n).map(|k| -2e-6 * k as f32).collect();
            write_corr(&mut p, &mut t, &corr2);
            assert!(p.report().pending);
        }
        for i in 0..period_steps {
            let s = p.sample(&t);
            // The correction, linear between points.
            let k = i / steps as usize;
            let frac = (i % steps as usize) as f32 / steps as f32;
            let table = |kk: usize| {
                let kk = kk % n;
                if period < 2 {
                    1e-6 * kk as f32
                } else {
                    -2e-6 * kk as f32
                }
            };
            let want = table(k) + frac * (table(k + 1) - table(k));
            assert!((s.corr - want).abs() < 1e-12, "period {period} step {i}");
            match p.record(&mut t, err(period, i) * RPC) {
                Recorded::Within => assert!(i + 1 < period_steps),
                r => {
                    assert_eq!(i + 1, period_steps);
                    ends.push(r);
                }
            }
        }
        let d = p.report().done.unwrap();
        assert_eq!(d.period, period as u32);
        assert_eq!(d.generation, if period < 2 { 1 } else { 2 });
        let e: Vec<f32> = (0..period_steps).map(|i| err(period, i)).collect();
        let rms = (e.iter().map(|x| x * x).sum::<f32>() / e.len() as f32).sqrt();
        let peak = e.iter().fold(0.0f32, |a, x| a.max(x.abs()));
        assert!((d.rms - rms).abs() < 1e-5 * rms.max(1.0));
        assert!((d.peak - peak).abs() < 1e-5 * peak);
        // The bins, read back.
        p.take(
            &TableRequest::Read {
                which: Which::Err,
                start: 0,
                max: 64,
            },
            &mut t,
            Some(&mut c),
        );
        assert_eq!(c.samples as usize, n);
        for k in 0..n {
            let m = e[k * steps as usize..(k + 1) * steps as usize]
                .iter()
                .sum::<f32>()
                / steps as f32;
            assert!((c.values[k] - m).abs() < 1e-5 * m.abs().max(1.0), "bin {k}");
        }
    }
    assert_eq!(ends[0], Recorded::PeriodEnd);
    assert_eq!(ends[1], Recorded::PeriodEnd);
    let start = (origin * 65536) + (values[0] * 65536.0) as i64;
    assert_eq!(ends[2], Recorded::RunEnd(start));
    assert_eq!(p.report().state, TableState::Ready);
    assert!(!p.report().pending);
}

/// The first complete period of a correction is held: the periods after it play on (and are
/// counted) without replacing its figures or its bins, until `Next` (then the next complete
/// period is held) or a new correction (the period under way when it is asked for is kept but
/// not held — it was not played wholly with it —, the first of the new one is held).
#[test]
fn a_period_is_held_until_the_host_asks_for_the_next() {
    let n = 8usize;
    let steps = 3u32;
    let values: Vec<f32> = (0..n).map(|k| k as f32 * 0.5).collect();
    let (mut p, mut t) = player(&values, steps, 0);
    let mut c = chunk();
    p.take(&TableRequest::Run(1000), &mut t, Some(&mut c));
    p.set_started(0, RPC, RATE);
    let per = n * steps as usize;
    // Period q's error: q everywhere (its bins and RMS say which period they are).
    let play = |p: &mut Player, t: &mut Vec<f32>, q: usize| {
        for _ in 0..per {
            p.sample(t);
            p.record(t, q as f32 * RPC);
        }
    };
    let bins = |p: &mut Player, t: &mut Vec<f32>, c: &mut Chunk| {
        let read = TableRequest::Read {
            which: Which::Err,
            start: 0,
            max: 64,
        };
        p.take(&read, t, Some(c));
        c.values[..n].to_vec()
    };
    for q in 0..4 {
        play(&mut p, &mut t, q);
    }
    let r = p.report();
    assert_eq!(r.period, 4, "every period counted");
    let d = r.done.unwrap();
    assert!(r.held);
    assert_eq!((d.period, d.generation), (0, 0));
    assert!(d.rms.abs() < 1e-4, "{d:?}");
    assert!(bins(&mut p, &mut t, &mut c).iter().all(|v| v.abs() < 1e-4));
    // Next: the period under way (4) is the next complete one, and is held.
    p.take(&TableRequest::Next, &mut t, None);
    assert!(!p.report().held);
    for q in 4..6 {
        play(&mut p, &mut t, q);
    }
    let d = p.report().done.unwrap();
    assert!(p.report().held);
    assert_eq!(d.period, 4);
    assert!((d.rms - 4.0).abs() < 1e-3, "{d:?}");
    assert!(
        bins(&mut p, &mut t, &mut c)
            .iter()
            .all(|v| (v - 4.0).abs() < 1e-3)
    );
    // Period 6 passes; a correction asked for within period 7 releases the one held: period 7
    // is kept but not held (not played wholly with it); period 8, its first, is held.
    play(&mut p, &mut t, 6);
    let corr: Vec<f32> = vec![1e-6; n];
    for _ in 0..per / 2 {
        p.sample(&t);
        p.record(&mut t, 7.0 * RPC);
    }
    write_corr(&mut p, &mut t, &corr);
    assert!(!p.report().held && p.report().pending);
    for _ in 0..per / 2 {
        p.sample(&t);
        p.record(&mut t, 7.0 * RPC);
    }
    let (d, r) = (p.report().done.unwrap(), p.report());
    assert_eq!((d.period, d.generation, r.held), (7, 0, false));
    for q in 8..11 {
        play(&mut p, &mut t, q);
    }
    let (d, r) = (p.report().done.unwrap(), p.report());
    assert_eq!((d.period, d.generation, r.held), (8, 1, true));
    assert!(
        bins(&mut p, &mut t, &mut c)
            .iter()
            .all(|v| (v - 8.0).abs() < 1e-3)
    );
    // A new run starts with nothing held.
    p.take(&TableRequest::Stop, &mut t, None);
    play(&mut p, &mut t, 11);
    assert_eq!(p.report().state, TableState::Ready);
    p.take(&TableRequest::Run(10), &mut t, Some(&mut c));
    assert!(!p.report().held && p.report().done.is_none());
}

/// `Stop` ends the run at the end of the period under way; `abort` at once, taking a
/// correction that waits; a reference written while playing is ignored.
#[test]
fn stop_abort_and_no_reference_write_while_playing() {
    let values: Vec<f32> = (0..8).map(|k| k as f32).collect();
    let values: Vec<f32> = values.iter().chain(values.iter().rev()).copied().collect();
    let (mut p, mut t) = player(&values, 2, 0);
    let mut c = chunk();
    p.take(&TableRequest::Run(100), &mut t, Some(&mut c));
    for _ in 0..3 {
        p.record(&mut t, 0.0);
    }
    p.take(&TableRequest::Stop, &mut t, Some(&mut c));
    let before = t[0];
    p.take(
        &TableRequest::Write {
            which: Which::Ref,
            start: 0,
            n: 1,
            values: [99.0; 8],
        },
        &mut t,
        Some(&mut c),
    );
    assert_eq!(t[0], before);
    let mut steps = 3;
    while p.report().state == TableState::Playing {
        p.record(&mut t, 0.0);
        steps += 1;
    }
    assert_eq!(steps, 32, "the period's end");
    assert_eq!(p.report().period, 1);
    // Abort.
    p.take(&TableRequest::Run(100), &mut t, Some(&mut c));
    write_corr(&mut p, &mut t, &[1e-6; 16]);
    assert!(p.report().pending);
    p.abort();
    let r = p.report();
    assert_eq!(r.state, TableState::Ready);
    assert!(!r.pending);
    assert_eq!(r.generation, 1);
}

/// The protocol side's checks: blocks in order, finite values, the whole reference, a
/// geometry the loop can play, no jump beyond the speed limit (the closing chord included),
/// within the soft limits.
#[test]
fn uploads_are_checked_before_anything_plays() {
    let g = |points, steps, origin| Geometry {
        points,
        steps,
        origin,
    };
    let vmax = 20.0;
    let lim = (-1_000_000i64, 1_000_000i64);
    let mut u = Upload::default();
    assert_eq!(u.write_ref(8, &[0.0; 8]), Err(TableError::OutOfOrder));
    assert_eq!(u.write_ref(0, &[f32::NAN]), Err(TableError::BadValue));
    u.write_ref(0, &[0.0, 10.0, 20.0, 10.0]).unwrap();
    assert_eq!(u.ref_next, 4);
    assert_eq!(
        u.check_set(&g(5, 1, 0), RATE, RPC, vmax, lim),
        Err(TableError::NotWhole)
    );
    assert_eq!(
        u.check_set(&g(3, 1, 0), RATE, RPC, vmax, lim),
        Err(TableError::BadGeometry)
    );
    assert_eq!(
        u.check_set(&g(4, 0, 0), RATE, RPC, vmax, lim),
        Err(TableError::BadGeometry)
    );
    assert_eq!(
        u.check_set(&g(4, 1_600_000_000, 0), RATE, RPC, vmax, lim),
        Err(TableError::BadGeometry)
    );
    u.check_set(&g(4, 1, 0), RATE, RPC, vmax, lim).unwrap();
    // 20 rad/s at 10 kHz and 3.8 µrad/count: 526 counts a step. A chord of 600 counts in
    // one step is a jump; ten steps apart it is 158 rad/s / 10: allowed.
    let mut j = Upload::default();
    j.write_ref(0, &[0.0, 600.0, 600.0, 0.0]).unwrap();
    assert_eq!(
        j.check_set(&g(4, 1, 0), RATE, RPC, vmax, lim),
        Err(TableError::TooFast)
    );
    j.check_set(&g(4, 10, 0), RATE, RPC, vmax, lim).unwrap();
    // The closing chord counts too.
    let mut k = Upload::default();
    k.write_ref(0, &[0.0, 100.0, 300.0, 600.0]).unwrap();
    assert_eq!(
        k.check_set(&g(4, 1, 0), RATE, RPC, vmax, lim),
        Err(TableError::TooFast)
    );
    // The stroke: the origin moves the whole table.
    assert_eq!(
        u.check_set(&g(4, 1, 999_990), RATE, RPC, vmax, lim),
        Err(TableError::OutOfStroke)
    );
    assert_eq!(
        u.check_set(&g(4, 1, -1_000_001), RATE, RPC, vmax, lim),
        Err(TableError::OutOfStroke)
    );
    u.check_set(&g(4, 1, 999_980), RATE, RPC, vmax, lim)
        .unwrap();
    // More than the table holds.
    let mut big = Upload::default();
    for b in 0..TABLE_POINTS / 8 {
        big.write_ref((b * 8) as u32, &[0.0; 8]).unwrap();
    }
    assert_eq!(
        big.write_ref(TABLE_POINTS as u32, &[0.0]),
        Err(TableError::TooMany)
    );
    // A correction: within the torque, in order, within the points.
    let mut cu = Upload::default();
    assert_eq!(
        cu.write_corr(0, &[1e-3], 4, 5e-4),
        Err(TableError::BadValue)
    );
    assert_eq!(
        cu.write_corr(0, &[0.0; 5], 4, 5e-4),
        Err(TableError::TooMany)
    );
    cu.write_corr(0, &[1e-4, -1e-4], 4, 5e-4).unwrap();
    assert_eq!(
        cu.write_corr(3, &[0.0], 4, 5e-4),
        Err(TableError::OutOfOrder)
    );
    cu.write_corr(2, &[0.0, 0.0], 4, 5e-4).unwrap();
    assert_eq!(cu.corr_next, 4);
}
