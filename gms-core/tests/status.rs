//! The `status` reply: what the device writes, a host reads back (one format, one parser).

use gms_core::control::controller::FfMode;
use gms_core::device::{DriveKind, StatusError, StatusReply};
use gms_core::drive::Faults;
use proptest::prelude::*;

fn written(s: &StatusReply) -> String {
    let mut out = String::new();
    s.write(&mut out).unwrap();
    out
}

/// An f32 as a reader gets it back: the f64 of its shortest decimal text.
fn as_read(x: f32) -> f64 {
    gms_core::numtext::Num(x).to_string().parse().unwrap()
}

fn any_reply() -> impl Strategy<Value = StatusReply> {
    let f = || prop::num::f32::NORMAL | prop::num::f32::ZERO | prop::num::f32::SUBNORMAL;
    (
        (
            prop::sample::select(FfMode::ALL.to_vec()),
            any::<bool>(),
            any::<u16>(),
            f(),
            f(),
            f(),
            any::<bool>(),
            f(),
        ),
        (
            f(),
            f(),
            f(),
            f(),
            f(),
            any::<u32>(),
            any::<u32>(),
            f(),
            any::<u32>(),
            f(),
            prop::sample::select(DriveKind::ALL.to_vec()),
            any::<bool>(),
        ),
    )
        .prop_map(
            |((mode, enabled, faults, t, pos, error_counts, moving, current), rest)| {
                let (
                    ff,
                    duty,
                    worst,
                    mean,
                    offset,
                    missed,
                    late,
                    duty_max,
                    duty_limited,
                    supply,
                    drive,
                    configured,
                ) = rest;
                StatusReply {
                    mode,
                    enabled,
                    faults: Faults(faults),
                    t: as_read(t),
                    pos: as_read(pos),
                    error_counts,
                    moving,
                    current,
                    ff,
                    duty,
                    step_us_worst: worst,
                    step_us_mean: mean,
                    sense_offset: offset,
                    missed,
                    late,
                    duty_max,
                    duty_limited,
                    supply,
                    drive,
                    configured,
                }
            },
        )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(1000))]

    /// Whatever the device writes reads back exactly (every finite f32, every fault word,
    /// every mode and drive).
    #[test]
    fn a_written_reply_reads_back_the_same(s in any_reply()) {
        let text = written(&s);
        prop_assert_eq!(StatusReply::parse(&text), Ok(s), "{}", text);
    }
}

#[test]
fn a_reply_without_a_key_is_refused_naming_it_and_unknown_keys_are_ignored() {
    let s = StatusReply {
        mode: FfMode::Gms,
        enabled: true,
        faults: Faults::OVER_CURRENT,
        t: 1.5,
        pos: -0.25,
        error_counts: 3.0,
        moving: false,
        current: 0.125,
        ff: 2e-4,
        duty: -0.5,
        step_us_worst: 12.0,
        step_us_mean: 9.5,
        sense_offset: 2048.25,
        missed: 2,
        late: 1,
        duty_max: 0.43,
        duty_limited: 7,
        supply: 23.75,
        drive: DriveKind::Current,
        configured: true,
    };
    let text = written(&s);
    assert!(text.contains(" fault_names=over_current "), "{text}");
    let words: Vec<&str> = text.split_whitespace().collect();
    assert_eq!(words.len(), 21, "{text}");
    for (i, w) in words.iter().enumerate() {
        let key = w.split_once('=').unwrap().0;
        let without: Vec<&str> = words
            .iter()
            .enumerate()
            .filter(|&(j, _)| j != i)
            .map(|(_, w)| *w)
            .collect();
        let r = StatusReply::parse(&without.join(" "));
        if key == "fault_names" {
            assert_eq!(r, Ok(s));
        } else {
            assert_eq!(
                r.map_err(|e| (e.key, e.bad_value)),
                Err((key, false)),
                "{key}"
            );
        }
    }
    assert_eq!(
        StatusReply::parse(&format!("{text} temperature=31.5 new_key")),
        Ok(s)
    );
    let e = StatusReply::parse(&text.replace("enabled=1", "enabled=yes")).unwrap_err();
    assert_eq!(
        e,
        StatusError {
            reply: "status",
            key: "enabled",
            bad_value: true
        }
    );
    assert_eq!(e.to_string(), "the status reply's enabled does not parse");
    assert!(StatusReply::parse(&text.replace("drive=current", "drive=torque")).is_err());
    assert!(StatusReply::parse(&text.replace("mode=gms", "mode=magic")).is_err());
}

proptest! {
    /// The entries are the written reply's words, in its order, with its values.
    #[test]
    fn the_entries_are_the_written_words(s in any_reply()) {
        use gms_core::device::StatusValue;
        let text = written(&s);
        let words: Vec<(&str, &str)> =
            text.split_whitespace().map(|w| w.split_once('=').unwrap()).collect();
        let entries = s.entries();
        prop_assert_eq!(words.len(), entries.len());
        for ((k, v), (key, value)) in words.iter().zip(entries) {
            prop_assert_eq!(*k, key);
            match value {
                StatusValue::Number(x) => {
                    // f32 values as f32; the position, the time and the integers as f64.
                    let as_f32 = v.parse::<f32>().unwrap() as f64;
                    let as_f64 = v.parse::<f64>().unwrap();
                    let wide = matches!(
                        key,
                        "t" | "pos" | "missed" | "late" | "duty_limited" | "faults"
                    );
                    prop_assert_eq!(x, if wide { as_f64 } else { as_f32 }, "{}: {}", key, v);
                }
                StatusValue::Text(t) => prop_assert_eq!(t, *v),
                StatusValue::Faults(f) => {
                    let mut names = String::new();
                    f.write_names(&mut names).unwrap();
                    prop_assert_eq!(names.as_str(), *v);
                }
            }
        }
    }
}
