//! The replies that carry data: whatever the device writes, a host reads back the same (one
//! format, one parser per reply), and a reply that lacks a key is refused naming it.

use gms_core::control::frf::{FrfState, Injection};
use gms_core::control::table::{Geometry, PeriodError, TableReport, TableState};
use gms_core::device::CaptureState;
use gms_core::protocol::{
    self, CaptureStatus, FrfMeasure, FrfStatus, ListRange, ListRow, ListValue, ReplyError,
    TableStatus,
};
use proptest::prelude::*;

/// Any f32 but NaN (which is never equal to itself; NaN is checked on its own below).
fn num() -> impl Strategy<Value = f32> {
    prop::num::f32::NORMAL
        | prop::num::f32::ZERO
        | prop::num::f32::SUBNORMAL
        | prop::num::f32::INFINITE
}

/// An f32 as a reader of f64 gets it back: the f64 of its shortest decimal text.
fn as_read(x: f32) -> f64 {
    gms_core::numtext::Num(x).to_string().parse().unwrap()
}

fn text(write: impl FnOnce(&mut String) -> core::fmt::Result) -> String {
    let mut s = String::new();
    write(&mut s).unwrap();
    s
}

fn any_capture() -> impl Strategy<Value = CaptureStatus> {
    (
        prop::sample::select(CaptureState::ALL.to_vec()),
        any::<u32>(),
        any::<u32>(),
        num(),
    )
        .prop_map(|(state, samples, capacity, origin)| CaptureStatus {
            state,
            samples,
            capacity,
            origin: as_read(origin),
        })
}

fn any_frf() -> impl Strategy<Value = FrfStatus> {
    let measure = (
        prop::sample::select(vec![Injection::Current, Injection::Position]),
        num(),
        num(),
        any::<u32>(),
        any::<u32>(),
        prop::array::uniform4(prop::array::uniform2(num())),
        prop::array::uniform4(num()),
    )
        .prop_map(
            |(injection, f_hz, amp, groups_done, groups, phasors, coherence)| FrfMeasure {
                injection,
                f_hz,
                amp,
                groups_done,
                groups,
                phasors,
                coherence,
            },
        );
    (
        prop::sample::select(FrfState::ALL.to_vec()),
        prop::option::of(measure),
    )
        .prop_map(|(state, measure)| FrfStatus { state, measure })
}

fn any_table() -> impl Strategy<Value = TableStatus> {
    let geometry =
        (any::<u32>(), any::<u32>(), any::<i64>()).prop_map(|(points, steps, origin)| Geometry {
            points,
            steps,
            origin,
        });
    let done =
        (any::<u32>(), any::<u32>(), num(), num()).prop_map(|(period, generation, rms, peak)| {
            PeriodError {
                period,
                generation,
                rms,
                peak,
            }
        });
    let report = (
        prop::sample::select(TableState::ALL.to_vec()),
        prop::option::of(geometry),
        (any::<u32>(), any::<u32>(), any::<u32>(), any::<bool>()),
        prop::option::of(done),
        any::<bool>(),
        0..=i64::MAX as u64,
    )
        .prop_map(
            |(state, geometry, (period, periods, generation, pending), done, held, started)| {
                TableReport {
                    state,
                    geometry,
                    period,
                    periods,
                    generation,
                    pending,
                    done,
                    held,
                    started,
                }
            },
        );
    prop::option::of(report).prop_map(TableStatus)
}

/// A word of a `list` line: no space, no bracket, not empty.
fn word() -> impl Strategy<Value = String> {
    "[a-z][a-z0-9._/·-]{0,12}"
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(1000))]

    #[test]
    fn a_capture_reply_reads_back_the_same(s in any_capture()) {
        let t = text(|o| s.write(o));
        prop_assert_eq!(CaptureStatus::parse(&t), Ok(s), "{}", t);
    }

    #[test]
    fn an_frf_reply_reads_back_the_same(s in any_frf()) {
        let t = text(|o| s.write(o));
        prop_assert_eq!(FrfStatus::parse(&t), Ok(s), "{}", t);
    }

    #[test]
    fn a_table_reply_reads_back_the_same(s in any_table()) {
        let t = text(|o| s.write(o));
        prop_assert_eq!(TableStatus::parse(&t), Ok(s), "{}", t);
    }

    #[test]
    fn a_row_reads_back_the_same(values in prop::collection::vec(num(), 1..12)) {
        let t = text(|o| protocol::write_row(o, &values));
        prop_assert!(t.ends_with('\n'));
        let back: Vec<f64> = protocol::row(t.trim_end()).collect::<Result<_, _>>().unwrap();
        let want: Vec<f64> = values.iter().map(|v| as_read(*v)).collect();
        prop_assert_eq!(back, want);
    }

    #[test]
    fn a_list_line_reads_back_the_same(
        path in word(),
        unit in word(),
        value in prop::option::of(num()),
        range in 0..3u8,
        min in num(),
        max in num(),
    ) {
        let value = match value {
            Some(x) => ListValue::Number(x),
            None => ListValue::Name("gms-adaptive"),
        };
        let range = match range {
            0 => ListRange::Number { min, max },
            1 => ListRange::Names(protocol::MODE_NAMES),
            _ => ListRange::ReadOnly,
        };
        let row = ListRow { path: &path, value, unit: &unit, range };
        let t = text(|o| row.write(o));
        prop_assert_eq!(ListRow::parse(t.trim_end()), Ok(row), "{}", t);
    }

    #[test]
    fn telemetry_reads_back_its_pairs(values in prop::collection::vec(num(), 1..8)) {
        let names = ["t", "pos", "ref", "err", "ff", "cur", "fric", "fric_true"];
        let mut line = String::new();
        for (n, v) in names.iter().zip(&values) {
            line += &format!(" {n}={}", gms_core::numtext::Num(*v));
        }
        let back: Vec<(&str, f64)> = protocol::telemetry(&line).collect();
        let want: Vec<(&str, f64)> =
            names.iter().copied().zip(values.iter().map(|v| as_read(*v))).collect();
        prop_assert_eq!(back, want);
    }
}

#[test]
fn a_coherence_not_yet_summed_reads_back_as_nan() {
    let s = FrfStatus {
        state: FrfState::Settling,
        measure: Some(FrfMeasure {
            injection: Injection::Current,
            f_hz: 40.0,
            amp: 0.2,
            groups_done: 0,
            groups: 4,
            phasors: [[0.2, 0.0], [0.0; 2], [0.0; 2], [0.0; 2]],
            coherence: [1.0, f32::NAN, f32::NAN, f32::NAN],
        }),
    };
    let t = text(|o| s.write(o));
    assert!(t.ends_with(" coh=1,NaN,NaN,NaN"), "{t}");
    let back = FrfStatus::parse(&t).unwrap().measure.unwrap();
    assert_eq!(back.coherence[0], 1.0);
    assert!(back.coherence[1..].iter().all(|c| c.is_nan()));
}

/// Each reply without one of its keys: refused naming it (keys that only go with another,
/// `steps` with `points`, are refused only with it). Unknown keys are skipped.
#[test]
fn a_reply_without_a_key_is_refused_naming_it() {
    fn drop_each(text: &str, parse: impl Fn(&str) -> Option<ReplyError>, optional: &[&str]) {
        let words: Vec<&str> = text.split(' ').collect();
        for i in 0..words.len() {
            let key = words[i].split_once('=').unwrap().0;
            let without: Vec<&str> = (0..words.len())
                .filter(|&j| j != i)
                .map(|j| words[j])
                .collect();
            let e = parse(&without.join(" "));
            if optional.contains(&key) {
                assert_eq!(e, None, "{key}");
            } else {
                let e = e.unwrap_or_else(|| panic!("{key} dropped, still read"));
                assert_eq!((e.key, e.bad_value), (key, false), "{key}");
            }
        }
        assert_eq!(parse(&format!("{text} later=1")), None);
    }
    let c = CaptureStatus {
        state: CaptureState::Done,
        samples: 10,
        capacity: 100,
        origin: 1.5,
    };
    drop_each(
        &text(|o| c.write(o)),
        |t| CaptureStatus::parse(t).err(),
        &[],
    );
    let f = FrfStatus {
        state: FrfState::Done,
        measure: Some(FrfMeasure {
            injection: Injection::Position,
            f_hz: 12.5,
            amp: 1e-3,
            groups_done: 4,
            groups: 4,
            phasors: [[1e-3, 0.0], [0.5, -0.25], [0.4, -0.2], [1e-3, 2e-4]],
            coherence: [1.0, 0.99, 0.98, 0.999],
        }),
    };
    // Without `inj` it is a reply of no measurement, which reads.
    drop_each(
        &text(|o| f.write(o)),
        |t| FrfStatus::parse(t).err(),
        &["inj"],
    );
    let t = TableStatus(Some(TableReport {
        state: TableState::Playing,
        geometry: Some(Geometry {
            points: 100,
            steps: 4,
            origin: -12,
        }),
        period: 3,
        periods: 10,
        generation: 2,
        pending: false,
        done: Some(PeriodError {
            period: 2,
            generation: 2,
            rms: 0.4,
            peak: 1.25,
        }),
        held: true,
        started: 1234,
    }));
    drop_each(
        &text(|o| t.write(o)),
        |x| TableStatus::parse(x).err(),
        &["points", "done"],
    );
    let e = TableStatus::parse("state=playing period=x").unwrap_err();
    assert_eq!(e.to_string(), "the table reply's period does not parse");
    assert_eq!(TableStatus::parse("state=none"), Ok(TableStatus(None)));
    assert!(ListRow::parse("pos.kp 0.2 A/rad").is_err());
    assert!(ListRow::parse("pos.kp 0.2 [0, 1]").is_err());
    assert!(protocol::row("1,x,3").any(|v| v.is_err()));
}
