//! Settings that survive a firmware update: a record written under one parameter table (an
//! older firmware) and loaded under another that adds, removes and re-ranges parameters keeps
//! every setting both know, clamps the re-ranged ones, leaves the new ones at their defaults
//! and names what it dropped; the position map is kept beside it in the store. A record of
//! the firmware before records kept ids (version 1) loads too.

use gms_core::device::store::{FlashStore, MAP_BUFFER_LEN, STORE_RANGE};
use gms_core::device::{
    self as record, LoadReport, RECORD_LEN, ReportLine, decode_settings, decode_settings_with,
    encode_settings_with, param_id,
};
use gms_core::device::{ParamStore, default_settings};
use gms_core::protocol::{Access, PARAMS, Param, Settings};

/// The parameter this test's "old firmware" had and the new one does not: it stands for a
/// setting since removed (it reads and writes a field both have, under a path only the old
/// table knows).
const GONE: &str = "pos.old_gain";

/// The old firmware's table: this firmware's, without `pos.ki_fric` and the second notch's
/// three settings (parameters "added since"), with one parameter of its own ([`GONE`]) and
/// `pos.kp` allowed up to 10 (this firmware's range is narrower for the test: see [`new_table`]).
fn old_table() -> Vec<Param> {
    let mut t: Vec<Param> = PARAMS
        .iter()
        .filter(|p| p.path != "pos.ki_fric" && !p.path.starts_with("filt.notch2."))
        .copied()
        .collect();
    t.push(Param {
        path: GONE,
        unit: "-",
        access: Access::Number {
            get: |s: &Settings| s.ff.static_band,
            set: |s: &mut Settings, v: f32| s.ff.static_band = v,
            min: 0.0,
            max: 10.0,
            integer: false,
        },
    });
    t
}

/// The new firmware's table: this firmware's, with `pos.kp` re-ranged to at most 0.3.
fn new_table() -> Vec<Param> {
    PARAMS
        .iter()
        .map(|p| match p.access {
            Access::Number {
                get, set, integer, ..
            } if p.path == "pos.kp" => Param {
                access: Access::Number {
                    get,
                    set,
                    min: 0.0,
                    max: 0.3,
                    integer,
                },
                ..*p
            },
            _ => *p,
        })
        .collect()
}

/// A commissioned axis: every common kind of setting moved off its default.
fn commissioned() -> Settings {
    let mut s = default_settings();
    s.pid.kp = 0.41;
    s.pid.ki = 512.0;
    s.pid.ki_fric = 0.2;
    s.motor.r = 7.25;
    s.motor.k_e = 5.5e-3;
    s.ff.gain = 0.81;
    s.ff.actuator.stribeck.fs = 231e-6;
    s.ff.static_band = 0.02;
    s.shaping.notch[0].f_hz = 3_500.0;
    s.shaping.notch[0].q = 4.0;
    s.shaping.notch[0].depth_db = 12.0;
    s.shaping.notch[1].f_hz = 900.0;
    s.shaping.notch[1].q = 2.0;
    s.shaping.notch[1].depth_db = 6.0;
    s.ff.mode = gms_core::control::controller::FfMode::GmsAdaptive;
    s.validate().expect("the commissioned set is valid");
    s
}

fn lines(r: &LoadReport) -> Vec<ReportLine> {
    r.lines().collect()
}

#[test]
fn a_record_of_another_table_keeps_every_common_setting() {
    let saved = commissioned();
    let old = old_table();
    let rec = encode_settings_with(&saved, &old);
    let defaults = default_settings();
    let new = new_table();
    let loaded = decode_settings_with(&rec, &defaults, &new).expect("the old record loads");
    let s = loaded.settings;
    // Every parameter both tables have is the saved value (pos.kp clamped, below).
    let mut common = 0;
    for p in &new {
        let Access::Number { get, .. } = p.access else {
            continue;
        };
        let in_old = old.iter().any(|o| o.path == p.path);
        let want = match (in_old, p.path) {
            (true, "pos.kp") => 0.3,
            (true, _) => get(&saved),
            (false, _) => get(&defaults),
        };
        assert_eq!(get(&s), want, "{}", p.path);
        common += in_old as usize;
    }
    assert_eq!(s.ff.mode, saved.ff.mode);
    // GONE wrote the field of ff.static_band too: the new table loads it by that path.
    assert_eq!(s.ff.static_band, saved.ff.static_band);
    // The report: pos.kp clamped, GONE dropped (by id), the four added ones missing.
    let r = loaded.report;
    assert_eq!(r.kept as usize, common + 1, "the numbers and the mode");
    assert_eq!(
        lines(&r),
        vec![
            ReportLine::Clamped("pos.kp"),
            ReportLine::Dropped(param_id(GONE)),
            ReportLine::Missing("pos.ki_fric"),
            ReportLine::Missing("filt.notch2.f_hz"),
            ReportLine::Missing("filt.notch2.q"),
            ReportLine::Missing("filt.notch2.depth_db"),
        ]
    );
    assert!(!r.is_clean());
    let text: Vec<String> = r.lines().map(|l| l.to_string()).collect();
    assert_eq!(text[0], "stored pos.kp: clamped into its range");
    assert_eq!(
        text[1],
        format!(
            "stored setting {:#010x}: dropped (not a parameter here)",
            param_id(GONE)
        )
    );
    assert_eq!(text[2], "pos.ki_fric: not in the store, at its default");
}

#[test]
fn a_record_of_this_table_loads_clean_and_exact() {
    let saved = commissioned();
    let rec = record::encode_settings(&saved);
    let loaded = decode_settings(&rec, &default_settings()).unwrap();
    assert_eq!(loaded.settings, saved);
    assert!(loaded.report.is_clean(), "{:?}", loaded.report);
}

/// A version-1 record, as the firmware before this one wrote it (version, layout id of the
/// table, mode, one f32 per number in table order, 64 slots, CRC-32).
fn v1_record(s: &Settings) -> Vec<u8> {
    let mut out = vec![1u8];
    out.extend(record::layout_id().to_le_bytes());
    out.push(match s.ff.mode {
        gms_core::control::controller::FfMode::None => 0,
        gms_core::control::controller::FfMode::Static => 1,
        gms_core::control::controller::FfMode::Gms => 2,
        gms_core::control::controller::FfMode::GmsAdaptive => 3,
    });
    let mut values = vec![0u8; 4 * 64];
    let numbers = PARAMS.iter().filter_map(|p| match p.access {
        Access::Number { get, .. } => Some(get(s)),
        _ => None,
    });
    for (slot, v) in values.chunks_exact_mut(4).zip(numbers) {
        slot.copy_from_slice(&v.to_le_bytes());
    }
    out.extend(values);
    let crc = gms_core::crc::crc32(&out);
    out.extend(crc.to_le_bytes());
    out
}

#[test]
fn a_version_1_record_of_this_table_still_loads() {
    let saved = commissioned();
    let v1 = v1_record(&saved);
    assert_eq!(v1.len(), 1 + 4 + 1 + 4 * 64 + 4);
    // As the store hands it over: zero-padded to a record's length.
    let mut rec = [0u8; RECORD_LEN];
    rec[..v1.len()].copy_from_slice(&v1);
    let loaded = decode_settings(&rec, &default_settings()).unwrap();
    assert_eq!(loaded.settings, saved);
    assert!(loaded.report.is_clean());
    // Under another table its values cannot be told apart: refused, with the reason.
    assert_eq!(
        decode_settings_with(&rec, &default_settings(), &old_table()),
        Err(record::RecordError::Layout)
    );
}

/// A flash image of the store's range in memory (as `hil-sim serve --store` keeps one in a
/// file), NOR-like: programming only clears bits.
struct RamFlash(Vec<u8>);

impl embedded_storage_async::nor_flash::ErrorType for RamFlash {
    type Error = core::convert::Infallible;
}

impl embedded_storage_async::nor_flash::ReadNorFlash for RamFlash {
    const READ_SIZE: usize = 1;
    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        let at = (offset - STORE_RANGE.start) as usize;
        bytes.copy_from_slice(&self.0[at..at + bytes.len()]);
        Ok(())
    }
    fn capacity(&self) -> usize {
        STORE_RANGE.end as usize
    }
}

impl embedded_storage_async::nor_flash::NorFlash for RamFlash {
    const WRITE_SIZE: usize = gms_core::device::store::WORD_SIZE;
    const ERASE_SIZE: usize = gms_core::device::store::SECTOR_SIZE;
    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        let (a, b) = (
            (from - STORE_RANGE.start) as usize,
            (to - STORE_RANGE.start) as usize,
        );
        self.0[a..b].fill(0xFF);
        Ok(())
    }
    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        let at = (offset - STORE_RANGE.start) as usize;
        for (d, s) in self.0[at..at + bytes.len()].iter_mut().zip(bytes) {
            *d &= *s;
        }
        Ok(())
    }
}

fn store(image: Vec<u8>) -> FlashStore<RamFlash> {
    let buf: &'static mut [u8] = Box::leak(vec![0u8; MAP_BUFFER_LEN].into_boxed_slice());
    FlashStore::new(RamFlash(image)).with_map_buffer(buf)
}

/// The old firmware saves its settings and a position map; the new firmware, on the same
/// flash, loads every common setting and the map as it was.
#[test]
fn an_update_keeps_the_settings_and_the_map_in_the_store() {
    let saved = commissioned();
    let image = vec![0xFF; (STORE_RANGE.end - STORE_RANGE.start) as usize];
    let mut old = store(image);
    old.save(&encode_settings_with(&saved, &old_table()))
        .unwrap();
    // A map record: any bytes the store keeps under its own key (the map's own format is
    // tested in posmap's tests).
    let map: Vec<u8> = (0..200u32).map(|i| (i * 7 + 3) as u8).collect();
    old.map_buffer().unwrap()[..map.len()].copy_from_slice(&map);
    old.save_map(map.len()).unwrap();
    let image = old.into_flash().unwrap().0;

    let mut new = store(image);
    let rec = new.load().unwrap().expect("a record");
    let loaded = decode_settings_with(&rec, &default_settings(), &new_table()).unwrap();
    assert_eq!(loaded.settings.pid.ki, saved.pid.ki);
    assert_eq!(loaded.settings.shaping.notch[0], saved.shaping.notch[0]);
    assert_eq!(loaded.settings.ff.mode, saved.ff.mode);
    assert_eq!(loaded.report.dropped, 1);
    assert_eq!(loaded.report.missing, 4);
    assert_eq!(new.load_map().unwrap(), Some(map.len()));
    assert_eq!(&new.map_buffer().unwrap()[..map.len()], &map[..]);
}

/// Bad entries change nothing but themselves: a value that is not a number, an unknown mode
/// code, a count past the record are each refused or dropped, never half applied.
#[test]
fn bad_entries_are_dropped_or_refused() {
    let saved = commissioned();
    let defaults = default_settings();
    let mut rec = record::encode_settings(&saved);
    let resign = |rec: &mut [u8; RECORD_LEN]| {
        let crc = gms_core::crc::crc32(&rec[..RECORD_LEN - 4]);
        rec[RECORD_LEN - 4..].copy_from_slice(&crc.to_le_bytes());
    };
    // The entry of pos.kp holds NaN: dropped, pos.kp at its default, the rest kept.
    let kp = param_id("pos.kp");
    let at = (0..rec[1] as usize)
        .map(|i| 2 + 8 * i)
        .find(|&a| u32::from_le_bytes(rec[a..a + 4].try_into().unwrap()) == kp)
        .unwrap();
    rec[at + 4..at + 8].copy_from_slice(&f32::NAN.to_le_bytes());
    resign(&mut rec);
    let l = decode_settings(&rec, &defaults).unwrap();
    assert_eq!(l.settings.pid.kp, defaults.pid.kp);
    assert_eq!(l.settings.pid.ki, saved.pid.ki);
    assert_eq!(lines(&l.report), vec![ReportLine::Dropped(kp)]);
    // A count past the room: the record is refused whole.
    let mut big = record::encode_settings(&saved);
    big[1] = 200;
    resign(&mut big);
    assert_eq!(
        decode_settings(&big, &defaults),
        Err(record::RecordError::Invalid)
    );
}
