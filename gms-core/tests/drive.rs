//! The motor driver's pure logic (count extension, current scaling, faults, step statistics,
//! bridge PWM, the flash record), against independent expectations.

use gms_core::crc::crc32;
use gms_core::device::{
    self as record, RECORD_LEN, RecordError, ReportLine, decode_settings, encode_settings,
};
use gms_core::drive::{
    self, CountExtender, CurrentSense, Faults, Limits, Measured, OffsetCalibration, StepStats,
    bridge_compare, pwm_timing, wrapping_delta,
};
use gms_core::protocol::{self, Access, PARAMS};
use gms_core::selftest;
use proptest::prelude::*;

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    /// Any sequence of increments smaller than half the counter's range: the extended count
    /// is the true sum, whatever the counter started at and however often it wrapped.
    #[test]
    fn extension_equals_true_sum(
        bits in prop::sample::select(vec![16u32, 32]),
        start in any::<u32>(),
        steps in prop::collection::vec(any::<i64>(), 1..400),
    ) {
        let half = 1i64 << (bits - 1);
        let mask = if bits == 32 { u32::MAX as u64 } else { (1u64 << bits) - 1 };
        let mut truth: i64 = 0;
        let raw_of = |t: i64| ((start as i64 + t) as u64 & mask) as u32;
        let mut ext = CountExtender::new(bits, raw_of(0));
        for s in steps {
            let d = s % half; // |d| < half
            truth += d;
            let got = ext.update(raw_of(truth));
            prop_assert_eq!(got, d);
            prop_assert_eq!(ext.count(), truth);
        }
    }

    /// The flash record of any valid set reads back as the same set.
    #[test]
    fn record_round_trips(idx in prop::collection::vec((0usize..64, 0.0f64..1.0), 0..20)) {
        let base = selftest::controller_params();
        let mut s = base;
        for (i, u) in idx {
            let p = &PARAMS[i % PARAMS.len()];
            if let Access::Number { min, max, .. } = p.access {
                // Log-uniform within the range where it is wide.
                let v = if min > 0.0 && max / min > 100.0 {
                    (min as f64 * (max as f64 / min as f64).powf(u)) as f32
                } else {
                    (min as f64 + (max - min) as f64 * u) as f32
                };
                if let Ok(n) = protocol::with_value(&s, p.path, &format!("{v:e}")) {
                    s = n;
                }
            }
        }
        let rec = encode_settings(&s);
        let back = decode_settings(&rec, &base).map(|l| (l.settings, l.report.is_clean()));
        prop_assert_eq!(back, Ok((s, true)));
    }

    /// Any corrupted byte is caught (the CRC), never half applied.
    #[test]
    fn corrupted_record_is_rejected(pos in 0usize..RECORD_LEN, flip in 1u8..=255) {
        let base = selftest::controller_params();
        let mut rec = encode_settings(&base);
        rec[pos] ^= flip;
        // The version byte turned into the first format's (1): that format is shorter, and
        // the bytes past its end are not zero.
        let expected = if pos == 0 && rec[0] == 1 {
            RecordError::Length
        } else {
            RecordError::Checksum
        };
        prop_assert_eq!(decode_settings(&rec, &base), Err(expected));
    }
}

#[test]
fn wrapping_delta_examples() {
    assert_eq!(wrapping_delta(65_530, 5, 16), 11);
    assert_eq!(wrapping_delta(5, 65_530, 16), -11);
    assert_eq!(wrapping_delta(4_294_967_290, 5, 32), 11);
    assert_eq!(wrapping_delta(100, 100, 32), 0);
}

/// Re-signs a record whose body was edited, so that the check behind the CRC is reached.
fn resign(rec: &mut [u8; RECORD_LEN]) {
    let crc = crc32(&rec[..RECORD_LEN - 4]);
    rec[RECORD_LEN - 4..].copy_from_slice(&crc.to_le_bytes());
}

#[test]
fn crc32_is_zlibs() {
    // The standard check value of CRC-32/ISO-HDLC.
    assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
}

#[test]
fn bad_records_name_why() {
    let base = selftest::controller_params();
    let good = encode_settings(&base);
    assert_eq!(
        decode_settings(&good[..10], &base),
        Err(RecordError::Length)
    );
    assert_eq!(
        decode_settings(&[0xff; RECORD_LEN], &base),
        Err(RecordError::Checksum)
    );
    let mut v = good;
    v[0] = 99;
    resign(&mut v);
    assert_eq!(decode_settings(&v, &base), Err(RecordError::Version));
    // A version-1 record (no ids) of another table.
    let mut l = [0u8; RECORD_LEN];
    l[0] = 1;
    l[1..5].copy_from_slice(&(record::layout_id() ^ 1).to_le_bytes());
    let crc = crc32(&l[..266 - 4]);
    l[266 - 4..266].copy_from_slice(&crc.to_le_bytes());
    assert_eq!(decode_settings(&l, &base), Err(RecordError::Layout));
    // The entries: the first is rate.pos_hz's. A value that makes the set invalid (cur_hz no
    // longer a multiple): refused whole. Out of range: clamped and named. Not a number:
    // dropped and named. No such mode (the mode's entry): dropped, the default kept.
    let pos_hz = record::param_id("rate.pos_hz");
    assert_eq!(u32::from_le_bytes(good[2..6].try_into().unwrap()), pos_hz);
    let with = |at: usize, v: f32| {
        let mut r = good;
        r[at..at + 4].copy_from_slice(&v.to_le_bytes());
        resign(&mut r);
        decode_settings(&r, &base)
    };
    assert_eq!(with(6, 7_777.0), Err(RecordError::Invalid));
    assert_eq!(
        with(6, 1e9),
        Err(RecordError::Invalid),
        "clamped to 50 kHz: not a divisor"
    );
    let nan = with(6, f32::NAN).unwrap();
    assert_eq!(nan.settings, base);
    assert_eq!(
        nan.report.lines().collect::<Vec<_>>(),
        [ReportLine::Dropped(pos_hz)]
    );
    // The byte offset of `path`'s entry in the record.
    let entry_at = |path: &str| {
        (0..good[1] as usize)
            .map(|i| 2 + 8 * i)
            .find(|&a| {
                u32::from_le_bytes(good[a..a + 4].try_into().unwrap()) == record::param_id(path)
            })
            .unwrap()
    };
    let m = with(entry_at("ff.mode") + 4, 7.0).unwrap();
    assert_eq!(m.settings.ff.mode, base.ff.mode);
    assert_eq!(m.report.dropped, 1);
    // pos.kp out of range: clamped to its maximum, named.
    let k = with(entry_at("pos.kp") + 4, 5e3).unwrap();
    assert_eq!(k.settings.pid.kp, 1e3);
    assert_eq!(
        k.report.lines().collect::<Vec<_>>(),
        [ReportLine::Clamped("pos.kp")]
    );
}

#[test]
fn the_table_fits_a_record() {
    let numbers = PARAMS
        .iter()
        .filter(|p| matches!(p.access, Access::Number { .. }))
        .count();
    assert!(numbers <= record::MAX_NUMBERS, "{numbers} parameters");
}

#[test]
fn current_scaling() {
    // 3.3 V reference, 12 bits, 68 mohm shunt into a gain of 50 (3.4 V/A), offset at mid.
    let cs = CurrentSense::new(3.3, 4095.0, 3.4, 2048.0).unwrap();
    let per_code = 3.3 / 4095.0 / 3.4;
    assert_eq!(cs.amps(2048), 0.0);
    assert!((cs.amps(3048) - 1000.0 * per_code).abs() < 1e-6);
    assert!((cs.amps(1048) + 1000.0 * per_code).abs() < 1e-6);
    assert!((cs.amps_sum(4 * 2148, 4) - 100.0 * per_code).abs() < 1e-6);
    assert_eq!(cs.amps_sum(123, 0), 0.0);
    // Range: the nearer rail, 2047 codes down.
    assert!((cs.range(4095.0) - 2047.0 * per_code).abs() < 1e-6);
    assert!(CurrentSense::new(3.3, 4095.0, 0.0, 2048.0).is_none());
    assert!(CurrentSense::new(f32::NAN, 4095.0, 3.4, 2048.0).is_none());
    assert!(CurrentSense::new(3.3, 4095.0, 3.4, -1.0).is_none());
}

#[test]
fn offset_calibration() {
    let mut c = OffsetCalibration::default();
    assert_eq!(c.finish(2048.0, 200.0), None);
    for code in [2040u32, 2050, 2060, 2050] {
        c.push(code);
    }
    assert_eq!(c.samples(), 4);
    assert_eq!(c.finish(2048.0, 200.0), Some(2050.0));
    // A disconnected amplifier reads 0: outside the window.
    let mut d = OffsetCalibration::default();
    d.push(0);
    assert_eq!(d.finish(2048.0, 200.0), None);
}

fn limits() -> Limits {
    Limits {
        period_cycles: 8400,
        i_trip: 0.75,
        max_error: 0.01,
        max_step_counts: 2_000,
        pos_min: -1_000_000,
        pos_max: 1_000_000,
        budget_cycles: 6_720,
        duty_max: 1.0,
    }
}

#[test]
fn each_fault_alone() {
    let ok = Measured {
        current: 0.1,
        error: 1e-4,
        delta: 10,
        periods: 1,
        pos: 500,
        cycles: 3_000,
    };
    let lim = limits();
    assert_eq!(drive::check(&ok, &lim, true), Faults::NONE);
    let cases = [
        (
            Measured {
                current: -0.8,
                ..ok
            },
            Faults::OVER_CURRENT,
        ),
        (
            Measured {
                current: f32::NAN,
                ..ok
            },
            Faults::OVER_CURRENT,
        ),
        (Measured { error: 0.02, ..ok }, Faults::FOLLOWING_ERROR),
        (Measured { error: -0.02, ..ok }, Faults::FOLLOWING_ERROR),
        (
            Measured {
                delta: -2_001,
                ..ok
            },
            Faults::ENCODER_JUMP,
        ),
        (
            Measured {
                pos: 1_000_001,
                ..ok
            },
            Faults::POSITION_LIMIT,
        ),
        (
            Measured {
                pos: -1_000_001,
                ..ok
            },
            Faults::POSITION_LIMIT,
        ),
        (
            Measured {
                cycles: 6_721,
                ..ok
            },
            Faults::OVERRUN,
        ),
    ];
    for (m, want) in cases {
        assert_eq!(drive::check(&m, &lim, true), want, "{m:?}");
    }
    // Exactly at a limit is still fine.
    let edge = Measured {
        current: 0.75,
        error: 0.01,
        delta: 2_000,
        periods: 1,
        pos: 1_000_000,
        cycles: 6_720,
    };
    assert_eq!(drive::check(&edge, &lim, true), Faults::NONE);
    // After the loop stood still for 1000 periods (a flash erase), the increment of that
    // whole time is checked against 1000 periods' worth; one count more is a jump.
    let stood = Measured {
        delta: 2_000_000,
        periods: 1000,
        ..edge
    };
    assert_eq!(drive::check(&stood, &lim, false), Faults::NONE);
    assert_eq!(
        drive::check(
            &Measured {
                delta: 2_000_001,
                ..stood
            },
            &lim,
            false
        ),
        Faults::ENCODER_JUMP
    );
    // Bridge off: only the encoder is watched.
    let bad = Measured {
        current: 5.0,
        error: 1.0,
        delta: 5_000,
        periods: 1,
        pos: i64::MAX,
        cycles: u32::MAX,
    };
    assert_eq!(drive::check(&bad, &lim, false), Faults::ENCODER_JUMP);
}

#[test]
fn faults_latch_until_cleared() {
    let mut f = Faults::NONE;
    f.latch(Faults::OVERRUN);
    f.latch(Faults::NONE);
    f.latch(Faults::ENCODER_JUMP);
    assert!(f.contains(Faults::OVERRUN) && f.contains(Faults::ENCODER_JUMP));
    assert!(!f.contains(Faults::OVER_CURRENT));
    let mut names = String::new();
    f.write_names(&mut names).unwrap();
    assert_eq!(names, "encoder_jump,overrun");
    let mut names = String::new();
    Faults(0x8101).write_names(&mut names).unwrap();
    assert_eq!(names, "over_current,control_stall,unknown");
}

#[test]
fn step_statistics() {
    let mut s = StepStats::default();
    assert_eq!((s.worst(), s.mean(), s.count()), (0, 0.0, 0));
    let xs = [1200u32, 4000, 800, 2000];
    for x in xs {
        s.record(x);
    }
    assert_eq!(s.worst(), 4000);
    assert_eq!(s.last(), 2000);
    assert_eq!(s.count(), 4);
    assert_eq!(s.mean(), 2000.0);
    assert!((drive::cycles_to_us(8400.0, 168_000_000) - 50.0).abs() < 1e-4);
}

#[test]
fn bridge_outputs() {
    // Forward: IN1 high throughout (compare above the period), IN2 low for |duty|.
    assert_eq!(bridge_compare(0.25, 4200, true), (4201, 3150));
    assert_eq!(bridge_compare(-0.25, 4200, true), (3150, 4201));
    // Full scale and beyond: the PWM side low throughout.
    assert_eq!(bridge_compare(1.5, 4200, true), (4201, 0));
    assert_eq!(bridge_compare(-1.0, 4200, true), (0, 4201));
    // Zero and NaN: both high (brake); disabled: both low (coast).
    assert_eq!(bridge_compare(0.0, 4200, true), (4201, 4201));
    assert_eq!(bridge_compare(f32::NAN, 4200, true), (4201, 4201));
    assert_eq!(bridge_compare(0.5, 4200, false), (0, 0));
}

/// The ticks of one centre-aligned period (RM0090 §17.3.3: the counter counts 0 up to ARR,
/// then ARR down to 1) in which PWM mode 1's output is low (CNT >= CCR, §17.3.10).
fn low_ticks(ccr: u32, arr: u32) -> u32 {
    (0..arr)
        .chain((1..=arr).rev())
        .filter(|&cnt| cnt >= ccr)
        .count() as u32
}

/// Through a model of the timer: the PWM side is low (driving) for |duty| of the period to a
/// tick, the other side never; at no duty neither input is ever low, not even the one tick at
/// the top that a compare value equal to the period leaves (a 6 ns drive pulse per period).
#[test]
fn bridge_outputs_through_the_timer() {
    let arr = 4200u32;
    for k in 0..=200u32 {
        let duty = k as f32 / 200.0;
        for sign in [1.0f32, -1.0] {
            let (c1, c2) = bridge_compare(sign * duty, arr, true);
            let (drive, hold) = if sign > 0.0 { (c2, c1) } else { (c1, c2) };
            let want = (2.0 * duty * arr as f32).round() as u32;
            assert!(
                low_ticks(drive, arr).abs_diff(want) <= 1,
                "duty {duty}: {} ticks low, want {want}",
                low_ticks(drive, arr)
            );
            assert_eq!(low_ticks(hold, arr), 0, "the holding side at duty {duty}");
        }
    }
    assert_eq!(low_ticks(4200, arr), 1, "the glitch the old zero had");
}

#[test]
fn pwm_timer_settings() {
    // 168 MHz, center-aligned, 20 kHz: 4200 counts up and down, no prescaler.
    assert_eq!(pwm_timing(168_000_000, 20_000.0, 65_535), Some((0, 4200)));
    assert_eq!(pwm_timing(168_000_000, 10_000.0, 65_535), Some((0, 8400)));
    // 100 Hz needs the prescaler: 13 × 64615 × 2 ticks.
    assert_eq!(pwm_timing(168_000_000, 100.0, 65_535), Some((12, 64_615)));
    // Too fast for a useful resolution, nonsense rates.
    assert_eq!(pwm_timing(168_000_000, 1e6, 65_535), None);
    assert_eq!(pwm_timing(168_000_000, 0.0, 65_535), None);
    assert_eq!(pwm_timing(168_000_000, f32::NAN, 65_535), None);
}

#[test]
fn limits_from_settings_and_board() {
    let mut s = selftest::controller_params(); // i_max 0.4 A, 3.8 urad/count
    s.pos_min = -38.0;
    s.pos_max = 19.0;
    let b = gms_core::boards::f405::BOARD.limits; // 1.5 × i_max, 10 mrad, 100 rad/s, 168 MHz, 55 %
    let l = drive::limits_for(&s, &b, 0.48);
    // 1.5 × 0.4 A = 0.6 A exceeds what the sense shows: capped at 95 % of 0.48 A.
    assert!((l.i_trip - 0.456).abs() < 1e-6);
    assert_eq!(l.max_error, 0.01);
    // 100 rad/s over a position period: at 20 kHz 5 mrad = 1315.8 counts, so 1316 (at
    // 10 kHz 2631.6, so 2632).
    let per_step = 100.0 / f64::from(s.pos_rate_hz) / f64::from(s.rad_per_count());
    assert_eq!(l.max_step_counts, per_step.ceil() as i64);
    // 38 rad / 3.8 urad = 1e7 counts, 19 rad 5e6 (f32 rounding of 3.8e-6 allows ±1).
    assert!((l.pos_min + 10_000_000).abs() <= 1, "{}", l.pos_min);
    assert!((l.pos_max - 5_000_000).abs() <= 1, "{}", l.pos_max);
    // 168 MHz / 40 kHz (the current loop's rate) = 4200 cycles, 75 % of it.
    assert_eq!(s.cur_rate_hz, 40_000.0);
    assert_eq!(l.budget_cycles, 3150);
    assert_eq!(l.period_cycles, 4200);
    assert!((drive::limits_for(&s, &b, 10.0).i_trip - 0.6).abs() < 1e-6);
}

/// The F405 board (gms-core's description) with a two-conversion sense chain (its zero at code
/// 2048 ± 150), so that a sum of codes reads as two.
fn sense_board() -> gms_core::device::Board {
    gms_core::device::Board {
        sense_oversample: 2,
        ..gms_core::boards::f405::BOARD
    }
}

#[test]
fn sense_zero_at_start() {
    use gms_core::device::{SenseTrouble, ZERO_SAMPLES, calibrate_sense};
    let board = sense_board();
    // Sums of two conversions alternating 2100+2101 and 2100+2100: the zero is 2100.25 codes.
    let mut i = 0u32;
    let z = calibrate_sense(&board, 3.4, || {
        i += 1;
        Some(if i % 2 == 0 { 4201 } else { 4200 })
    });
    assert_eq!(i, ZERO_SAMPLES);
    assert_eq!(z.faults, Faults::NONE);
    assert_eq!(z.trouble, SenseTrouble::None);
    assert_eq!(z.sense.offset, 2100.25);
    assert_eq!(z.sense.amps_per_code, 3.3f32 / 4095.0 / 3.4);
    // 151 codes off (per conversion): the amplifier is not what the board says.
    let z = calibrate_sense(&board, 3.4, || Some(2 * (2048 + 151)));
    assert_eq!(z.faults, Faults::CURRENT_SENSE);
    assert_eq!(z.trouble, SenseTrouble::OutOfWindow { mean_code: 2199.0 });
    assert_eq!(z.sense.offset, 2048.0);
    // 150 off is still inside; a dead amplifier (0) is not.
    assert!(
        calibrate_sense(&board, 3.4, || Some(2 * (2048 - 150)))
            .faults
            .is_empty()
    );
    assert_eq!(
        calibrate_sense(&board, 3.4, || Some(0)).faults,
        Faults::CURRENT_SENSE
    );
}

/// A dead sense chain (the ADC never triggered, its DMA stopped): the calibration asks for one
/// reading more after the last that came, not [`ZERO_SAMPLES`] of them, so that its time is
/// one of the shell's bounded waits (the firmware's: 1 ms) and not 256 of them, which once
/// outlasted the watchdog; the fault says why.
#[test]
fn a_dead_sense_chain_ends_the_calibration_at_once() {
    use gms_core::device::{SenseTrouble, ZERO_SAMPLES, calibrate_sense};
    let board = sense_board();
    // A model of the DMA: `alive` sequences complete, then none; each wait polls its flag up
    // to `bound` times.
    for alive in [0u32, 1, 17, ZERO_SAMPLES - 1] {
        let bound = 1_000u32;
        let (mut done, mut polls, mut calls) = (0u32, 0u64, 0u32);
        let z = calibrate_sense(&board, 3.4, || {
            calls += 1;
            for _ in 0..bound {
                polls += 1;
                if done < alive {
                    done += 1;
                    return Some(2 * 2048);
                }
            }
            None
        });
        assert_eq!(z.faults, Faults::CURRENT_SENSE, "{alive}");
        assert_eq!(z.trouble, SenseTrouble::NoSamples { taken: alive });
        assert_eq!(calls, alive + 1);
        assert_eq!(
            polls,
            alive as u64 + bound as u64,
            "one bound spent, {alive}"
        );
        assert_eq!(z.sense.offset, board.sense.zero_code);
    }
}

/// A model of a bridge input pin: the timer drives it while it is its alternate function,
/// else the GPIO latch does.
#[derive(Default)]
struct PinModel {
    timer_on: bool,
    timer_level: bool,
    latch: bool,
    gpio: bool,
    /// Every level the pin took.
    seen: Vec<bool>,
}

impl PinModel {
    fn level(&self) -> bool {
        if self.gpio {
            self.latch
        } else {
            self.timer_on && self.timer_level
        }
    }
    fn record(&mut self) {
        let l = self.level();
        self.seen.push(l);
    }
}

impl drive::BridgeOff for PinModel {
    fn disable_timer_outputs(&mut self) {
        self.timer_on = false;
        self.record();
    }
    fn latch_pins_low(&mut self) {
        self.latch = false;
        self.record();
    }
    fn pins_to_gpio_outputs(&mut self) {
        self.gpio = true;
        self.record();
    }
}

#[test]
fn bridge_off_never_drives_a_pin_high() {
    // From every state: the timer driving high or low, an old latch high or low, the pin
    // already a GPIO or not.
    for bits in 0..16u8 {
        let mut p = PinModel {
            timer_on: true,
            timer_level: bits & 1 != 0,
            latch: bits & 2 != 0,
            gpio: bits & 4 != 0,
            seen: Vec::new(),
        };
        if bits & 8 != 0 {
            // Already off once: the path is idempotent.
            drive::bridge_off(&mut p);
            p.seen.clear();
        }
        let before = p.level();
        drive::bridge_off(&mut p);
        assert!(!p.level(), "state {bits:04b}: the pin ends high");
        // No step of the path raises the pin (it may only fall).
        let mut last = before;
        for &l in &p.seen {
            assert!(
                !l || last,
                "state {bits:04b}: a step drove the pin high: {:?}",
                p.seen
            );
            last = l;
        }
        assert!(p.gpio && !p.latch && !p.timer_on);
    }
}

#[test]
fn encoder_input_filter() {
    // 84 MHz, 1 Mcount/s: edges 1 us apart, the window at most 0.5 us: f_DTS/4 with N = 8 is
    // 381 ns (f_DTS/8, N = 6 would be 571 ns).
    let (code, w) = drive::encoder_filter(84_000_000, 1e6);
    assert_eq!(code, 0b0111);
    assert!((w - 32.0 / 84e6).abs() < 1e-12, "{w}");
    // Slower encoders get stronger filters, never a window above half the edge spacing.
    let mut last = 0.0;
    for rate in [1e7f32, 3e6, 1e6, 3e5, 1e5, 3e4, 1e4] {
        let (c, w) = drive::encoder_filter(84_000_000, rate);
        assert!(w <= 0.5 / rate, "{rate}: {w}");
        assert!(w >= last, "{rate}: {w} below {last}");
        let (div, n) = drive::INPUT_FILTERS[c as usize];
        assert_eq!(w, (n * div) as f32 / 84e6);
        last = w;
    }
    // The strongest filter (f_DTS/32, N = 8: 3.05 us) once the edges are 6.1 us apart.
    assert_eq!(drive::encoder_filter(84_000_000, 1.6e5).0, 0b1111);
    // Too fast for any filter (2 samples at 84 MHz = 24 ns > half of 1/30 MHz), or nonsense.
    assert_eq!(drive::encoder_filter(84_000_000, 3e7), (0, 0.0));
    assert_eq!(drive::encoder_filter(0, 1e6), (0, 0.0));
    assert_eq!(drive::encoder_filter(84_000_000, f32::NAN), (0, 0.0));
    assert_eq!(drive::encoder_filter(84_000_000, -1.0), (0, 0.0));
}

#[test]
fn current_sense_trigger_timing() {
    // The F405 board: ADC at 84 MHz / 4 = 21 MHz, 16 conversions of 15 + 12 cycles, 2 cycles
    // of trigger latency.
    let t = drive::SenseTiming {
        adc_hz: 21_000_000,
        sample_cycles: 15,
        conversions: 16,
        latency_cycles: 2,
    };
    assert_eq!(t.conversion_cycles(), 27);
    // 2 + 16 × 27 = 434 cycles = 20.67 us.
    assert!((t.window_s() - 434.0 / 21e6).abs() < 1e-10);
    // Sampling instants at 2 + 15 + 27 k, k = 0..15: mean 2 + 15 + 7.5 × 27 = 219.5 cycles.
    let instants: Vec<f64> = (0..16).map(|k| (2 + 15 + 27 * k) as f64).collect();
    let centroid = instants.iter().sum::<f64>() / 16.0;
    assert_eq!(centroid, 219.5);
    assert!((t.lead_s() as f64 - centroid / 21e6).abs() < 1e-10);
    // In TIM8 counts at 168 MHz: 219.5 × 8 = 1756; with the prescaler at 1 (84 MHz), 878.
    assert_eq!(t.lead_counts(168_000_000, 0), 1756);
    assert_eq!(t.lead_counts(168_000_000, 1), 878);
    // One conversion: the lead is latency + sampling.
    let one = drive::SenseTiming {
        conversions: 1,
        ..t
    };
    assert_eq!(one.lead_counts(168_000_000, 0), 17 * 8);
    // A centred window: as much of it before the trigger's target as after (to a cycle).
    let before = t.lead_s() - (2.0 + 15.0) / 21e6;
    let after = t.window_s() - t.lead_s() - 12.0 / 21e6;
    assert!((before - after).abs() < 1.0 / 21e6, "{before} {after}");
}

#[test]
fn rates_the_current_sense_cannot_sample_are_refused() {
    use gms_core::device::{default_settings, prepare};
    // The F405 board: 8 conversions of 15 + 12 cycles and a 2-cycle latency at 21 MHz.
    let board = gms_core::boards::f405::BOARD;
    assert!((board.sense.window_s - (2.0 + 8.0 * 27.0) / 21e6).abs() < 1e-9);
    // 10.38 us of window against 2 × 0.25 × period: 20 kHz (25 us), 40 kHz (12.5 us) and
    // 48 kHz (10.42 us) run, 50 kHz (10 us) does not.
    let mut s = default_settings();
    for (hz, ok) in [
        (20_000.0, true),
        (40_000.0, true),
        (48_000.0, true),
        (50_000.0, false),
    ] {
        s.cur_rate_hz = hz;
        s.pos_rate_hz = hz / 2.0;
        let r = prepare(&s, &board);
        assert_eq!(r.is_ok(), ok, "{hz} Hz: {:?}", r.err());
        if !ok {
            assert_eq!(
                r.err(),
                Some("the board's current sense cannot sample at rate.cur_hz")
            );
        }
    }
}

#[test]
fn missed_periods_between_steps() {
    let p = 8400;
    // On time, early or late by less than half a period: none missed.
    for since in [8400, 8000, 12_599, 4201] {
        assert_eq!(drive::missed_periods(since, p), 0, "{since}");
    }
    // 1.5 periods and more: one, then one per period.
    assert_eq!(drive::missed_periods(12_600, p), 1);
    assert_eq!(drive::missed_periods(2 * p, p), 1);
    assert_eq!(drive::missed_periods(3 * p, p), 2);
    assert_eq!(drive::missed_periods(1000 * p, p), 999);
    // Not measured.
    assert_eq!(drive::missed_periods(0, p), 0);
    assert_eq!(drive::missed_periods(p, 0), 0);
    assert_eq!(drive::missed_periods(u32::MAX, 1), u32::MAX - 1);
}

/// A centre-aligned counter at `t` timer counts after a bottom: its value and whether it
/// counts down (at the top, `arr`, either way: the hardware's DIR there is not relied on).
fn centre_aligned(t: u64, arr: u64, top_down: bool) -> (u16, bool) {
    let p = t % (2 * arr);
    if p < arr || (p == arr && !top_down) {
        (p as u16, false)
    } else {
        ((2 * arr - p) as u16, true)
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2048))]

    /// Two readings of a centre-aligned counter less than a period apart: the later one is
    /// past the update exactly when a bottom (the update event, the counter at 0 counting up)
    /// lies after the first and at or before the second, whatever the period and wherever
    /// the readings fall, the top's direction read either way.
    #[test]
    fn a_duty_written_past_the_bottom_is_late(
        arr in 2u64..=0xFFFF,
        t1 in 0u64..1 << 40,
        frac in 0.0f64..1.0,
        top1 in any::<bool>(),
        top2 in any::<bool>(),
    ) {
        let d = ((2 * arr) as f64 * frac) as u64;
        let t2 = t1 + d;
        // One instant read twice reads one direction.
        let top2 = if d == 0 { top1 } else { top2 };
        let (c1, d1) = centre_aligned(t1, arr, top1);
        let (c2, d2) = centre_aligned(t2, arr, top2);
        let bottom_between = t2 / (2 * arr) > t1 / (2 * arr);
        prop_assert_eq!(
            drive::past_update(drive::pwm_phase(c1, d1), drive::pwm_phase(c2, d2)),
            bottom_between,
            "arr {} t1 {} t2 {}", arr, t1, t2
        );
    }
}

#[test]
fn a_late_step_is_counted_apart() {
    let mut s = StepStats::new();
    assert_eq!(s.late(), 0);
    s.record_late();
    s.record_late();
    assert_eq!((s.late(), s.missed()), (2, 0));
}

/// The dead-time compensation (`drive.dead_time`): the duty of a current step is the
/// voltage's plus `dead_time / T` towards the commanded current, linear within 2 % of
/// `lim.i_max` around zero; nothing with no dead time. Checked against the formula for a
/// 40 kHz loop (T = 25 µs): 220 ns is 0.0088 of the period.
#[test]
fn the_dead_time_is_added_back_towards_the_commanded_current() {
    use gms_core::control::controller::{Controller, DEAD_TIME_BAND};
    let mut s = gms_core::device::default_settings();
    s.cur_rate_hz = 40_000.0;
    s.dead_time = 220e-9;
    let band = DEAD_TIME_BAND * s.i_max;
    let mut c = Controller::try_new(s).unwrap();
    let share = 220e-9 * 40_000.0;
    for (amps, expect) in [
        (0.3, share),
        (-0.3, -share),
        (band, share),
        (0.5 * band, 0.5 * share),
        (-0.25 * band, -0.25 * share),
        (0.0, 0.0),
    ] {
        c.hold_current(amps);
        // The measured current equal to the command: the PI adds nothing but its feedforward
        // (R i), so the duty is R i / V plus the compensation.
        let out = c.current_step(amps);
        let comp = out.duty - out.voltage / s.v_supply;
        assert!(
            (comp - expect).abs() < 1e-6,
            "at {amps} A: {comp} against {expect}"
        );
        assert!((c.dead_time_duty() - comp).abs() < 1e-6);
    }
    // Without a dead time, the duty is the voltage's.
    s.dead_time = 0.0;
    let mut c = Controller::try_new(s).unwrap();
    c.hold_current(0.3);
    let out = c.current_step(0.3);
    assert_eq!(out.duty, out.voltage / s.v_supply);
    // Out of range: refused by the settings' check.
    s.dead_time = 6e-6;
    assert!(Controller::try_new(s).is_err());
}

/// The duty limit of the F4 boards' sense window, against the PWM's own geometry: with the
/// compare values `bridge_compare` writes (centre-aligned, the driving side low while the
/// counter is at or above the compare value, RM0090 §17.3.10), the drive pulse of every duty
/// up to `duty_max` ends, and the reading settles (`edge_settle_s`), before the window opens
/// (half the window before the bottom), and starts after it has closed; a duty 0.02 above it
/// puts the settling in the window. At 40 kHz about 0.43, at 20 kHz about 0.72; an ideal
/// sense has none.
#[test]
fn the_duty_limit_keeps_the_bridge_edges_out_of_the_sense_window() {
    let b = gms_core::boards::f405::BOARD;
    let sense = b.sense;
    for (hz, near) in [(40_000.0f32, 0.43f32), (20_000.0, 0.72)] {
        let dmax = sense.duty_max(hz);
        assert!((dmax - near).abs() < 0.01, "{hz} Hz: {dmax}");
        let (_, arr) = drive::pwm_timing(b.pwm_timer_hz, hz, b.pwm_max_arr).unwrap();
        let t = 1.0 / hz as f64;
        let half_window = sense.window_s as f64 / 2.0;
        let settle = sense.edge_settle_s as f64;
        // The pulse (CNT >= CCR) from CCR on the way up to CCR on the way down: the counter
        // takes T/2 from 0 to ARR.
        let pulse = |d: f32| {
            let (_, ccr) = drive::bridge_compare(d, arr, true);
            let up = ccr as f64 / arr as f64 * t / 2.0;
            (up, t - up)
        };
        for k in 1..=50 {
            let d = dmax * k as f32 / 50.0;
            let (start, end) = pulse(d);
            assert!(
                end + settle <= t - half_window + 1e-9,
                "{hz} Hz, duty {d}: settled at {:.2} us, the window opens at {:.2} us",
                (end + settle) * 1e6,
                (t - half_window) * 1e6
            );
            assert!(start >= half_window, "{hz} Hz, duty {d}");
        }
        let (_, end) = pulse(dmax + 0.02);
        assert!(
            end + settle > t - half_window,
            "{hz} Hz: {} over the limit",
            dmax + 0.02
        );
    }
    let ideal = gms_core::device::SenseChain {
        window_s: 0.0,
        edge_settle_s: 0.0,
        ..sense
    };
    assert_eq!(ideal.duty_max(40_000.0), 1.0);
}

/// The current loop under a duty limit: the voltage never exceeds `duty_max` × the supply,
/// however much the error asks, the duty stays within ±`duty_max` with the dead-time
/// compensation added, each such step says it was limited, and a command within reach is
/// not limited.
#[test]
fn the_current_loop_holds_its_duty_within_the_limit() {
    use gms_core::control::controller::Controller;
    let mut s = gms_core::device::default_settings();
    s.cur_rate_hz = 40_000.0;
    s.dead_time = 220e-9;
    let mut c = Controller::try_new(s).unwrap();
    c.set_duty_max(0.43);
    // A current the motor cannot reach from here (the measurement stays at 0): the integral
    // pushes until the limit holds it.
    c.hold_current(0.4);
    let mut limited = 0;
    for _ in 0..2_000 {
        let out = c.current_step(0.0);
        assert!(
            out.voltage.abs() <= 0.43 * s.v_supply + 1e-5,
            "{}",
            out.voltage
        );
        assert!(out.duty.abs() <= 0.43 + 1e-6, "{}", out.duty);
        limited += out.limited as u32;
    }
    assert!(limited > 1_900, "{limited} of 2000 steps limited");
    let out = c.current_step(0.0);
    assert!(
        (out.duty - 0.43).abs() < 1e-6,
        "held at the limit: {}",
        out.duty
    );
    // Both ways.
    c.hold_current(-0.4);
    for _ in 0..2_000 {
        c.current_step(0.0);
    }
    assert!((c.current_step(0.0).duty + 0.43).abs() < 1e-6);
    // Within reach: R i = 10.6 Ω × 0.1 A = 1.06 V, duty 0.09: not limited.
    let mut c = Controller::try_new(s).unwrap();
    c.set_duty_max(0.43);
    c.hold_current(0.1);
    let out = c.current_step(0.1);
    assert!(!out.limited);
    // Out-of-range limits: within 0 … 1, a NaN none.
    c.set_duty_max(1.5);
    assert_eq!(c.duty_max(), 1.0);
    c.set_duty_max(f32::NAN);
    assert_eq!(c.duty_max(), 1.0);
    c.set_duty_max(-1.0);
    assert_eq!(c.duty_max(), 0.0);
}
