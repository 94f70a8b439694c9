//! Power-cut safety of the parameter store (`gms_core::device::store::FlashStore`): a `save` is cut at
//! every write and erase it makes, before the operation, part-way through it (bytes of a word
//! half-programmed, part of a sector erased) and at its last byte; after the cut the flash is
//! powered again and the device restarts on it. The restart must find the record that was
//! there before the save or the new one, bit for bit, never an error or anything else; the
//! start-up decision (`device::startup`) must run one of the two sets without a fault; and the
//! store must take the next save. Three starting points: an empty store (first save), a store
//! with records, and a store whose next save fills its sector, so that the save migrates the
//! record and erases a sector (the riskiest case).
//!
//! The flash model is NOR as on the STM32F405 (RM0090 §3.5/3.6): programming only clears
//! bits, an erase sets a whole 128 KiB sector to 0xFF, words of 4 bytes as embassy-stm32 0.6
//! writes them.

use std::cell::RefCell;
use std::rc::Rc;

use embedded_storage_async::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};
use gms_core::device::store::{FlashStore, SECTOR_SIZE, STORE_RANGE, WORD_SIZE};
use gms_core::device::{ParamStore, default_settings, startup};
use gms_core::device::{RECORD_LEN, ReportLine, encode_settings, encode_settings_with};
use gms_core::drive::Faults;
use gms_core::protocol::{PARAMS, Param, Settings};

const IMAGE_LEN: usize = (STORE_RANGE.end - STORE_RANGE.start) as usize;

/// How an operation is cut.
#[derive(Debug, Clone, Copy)]
enum Part {
    /// The power fails before the operation changes anything.
    Before,
    /// `bytes` bytes done, the next byte half done (a write clears only every other bit it
    /// should; an erase leaves the byte as it was), the rest untouched.
    Within { bytes: usize },
}

/// One write or erase, as the save made it.
#[derive(Debug, Clone, Copy)]
enum Op {
    Write { len: usize },
    Erase,
}

#[derive(Debug)]
struct Shared {
    image: Vec<u8>,
    /// Writes and erases so far.
    ops: Vec<Op>,
    /// Cut at operation index `.0` as `.1`.
    cut: Option<(usize, Part)>,
    /// The power is off: every further operation fails.
    dead: bool,
}

/// A NOR flash over [`STORE_RANGE`] whose image is shared with the test, so that it
/// survives the store (the "power cut") and can be restarted on.
#[derive(Clone)]
struct CutFlash(Rc<RefCell<Shared>>);

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum CutError {
    PowerLost,
    Bounds,
}

impl NorFlashError for CutError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            CutError::PowerLost => NorFlashErrorKind::Other,
            CutError::Bounds => NorFlashErrorKind::OutOfBounds,
        }
    }
}

impl CutFlash {
    fn new(image: Vec<u8>, cut: Option<(usize, Part)>) -> CutFlash {
        assert_eq!(image.len(), IMAGE_LEN);
        CutFlash(Rc::new(RefCell::new(Shared {
            image,
            ops: Vec::new(),
            cut,
            dead: false,
        })))
    }

    fn image(&self) -> Vec<u8> {
        self.0.borrow().image.clone()
    }

    fn ops(&self) -> Vec<Op> {
        self.0.borrow().ops.clone()
    }

    fn span(offset: u32, len: usize) -> Result<std::ops::Range<usize>, CutError> {
        let start = offset
            .checked_sub(STORE_RANGE.start)
            .ok_or(CutError::Bounds)? as usize;
        let end = start + len;
        if end > IMAGE_LEN {
            return Err(CutError::Bounds);
        }
        Ok(start..end)
    }

    /// Records an operation of `op` and says how much of `len` bytes it may do (`None`: all).
    fn begin(&self, op: Op, len: usize) -> Result<Option<usize>, CutError> {
        let mut s = self.0.borrow_mut();
        if s.dead {
            return Err(CutError::PowerLost);
        }
        let index = s.ops.len();
        s.ops.push(op);
        match s.cut {
            Some((at, part)) if at == index => {
                s.dead = true;
                Ok(Some(match part {
                    Part::Before => 0,
                    Part::Within { bytes } => bytes.min(len),
                }))
            }
            _ => Ok(None),
        }
    }
}

impl ErrorType for CutFlash {
    type Error = CutError;
}

impl ReadNorFlash for CutFlash {
    const READ_SIZE: usize = 1;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), CutError> {
        let s = self.0.borrow();
        if s.dead {
            return Err(CutError::PowerLost);
        }
        let at = Self::span(offset, bytes.len())?;
        bytes.copy_from_slice(&s.image[at]);
        Ok(())
    }

    fn capacity(&self) -> usize {
        STORE_RANGE.end as usize
    }
}

impl NorFlash for CutFlash {
    const WRITE_SIZE: usize = WORD_SIZE;
    const ERASE_SIZE: usize = SECTOR_SIZE;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), CutError> {
        assert!(from % SECTOR_SIZE as u32 == 0 && to % SECTOR_SIZE as u32 == 0 && to >= from);
        let at = Self::span(from, (to - from) as usize)?;
        let done = self.begin(Op::Erase, at.len())?;
        let mut s = self.0.borrow_mut();
        let n = done.unwrap_or(at.len());
        s.image[at.start..at.start + n].fill(0xFF);
        match done {
            None => Ok(()),
            Some(_) => Err(CutError::PowerLost),
        }
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), CutError> {
        assert!(offset % WORD_SIZE as u32 == 0 && bytes.len() % WORD_SIZE == 0);
        let at = Self::span(offset, bytes.len())?;
        let done = self.begin(Op::Write { len: bytes.len() }, bytes.len())?;
        let mut s = self.0.borrow_mut();
        let dst = &mut s.image[at];
        let n = done.unwrap_or(bytes.len());
        // NOR: programming only clears bits.
        for (d, b) in dst.iter_mut().zip(bytes).take(n) {
            *d &= *b;
        }
        match done {
            None => Ok(()),
            Some(_) => {
                if let (Some(d), Some(b)) = (dst.get_mut(n), bytes.get(n)) {
                    // Half programmed: only every other bit that should clear has cleared.
                    *d &= !(!*b & 0x55);
                }
                Err(CutError::PowerLost)
            }
        }
    }
}

/// A distinct, valid parameter record number `i` (< 10 000).
fn record(i: u32) -> [u8; RECORD_LEN] {
    assert!(i < 10_000);
    let mut s: Settings = default_settings();
    // ff.gain runs 0..2: 0.5 + 1e-4·i stays inside and differs for every i.
    s.ff.gain = 0.5 + 1e-4 * i as f32;
    encode_settings(&s)
}

fn load(image: Vec<u8>) -> Result<Option<[u8; RECORD_LEN]>, gms_core::device::StoreError> {
    FlashStore::new(CutFlash::new(image, None)).load()
}

/// The image after saving records `0..n` on an empty store.
fn filled(n: u32) -> Vec<u8> {
    let flash = CutFlash::new(vec![0xFF; IMAGE_LEN], None);
    let mut store = FlashStore::new(flash.clone());
    for i in 0..n {
        store.save(&record(i)).expect("save on a healthy flash");
    }
    drop(store);
    flash.image()
}

/// The ways to cut operation `op`.
fn parts(op: Op) -> Vec<Part> {
    let len = match op {
        Op::Write { len } => len,
        Op::Erase => SECTOR_SIZE,
    };
    let mut v = vec![Part::Before, Part::Within { bytes: 0 }];
    for b in [1, WORD_SIZE - 1, WORD_SIZE, len / 2, len - 1] {
        if b > 0 && b < len {
            v.push(Part::Within { bytes: b });
        }
    }
    v
}

/// What a series of cuts found.
struct Found {
    /// Cuts tried.
    tried: usize,
    /// The save's operations (uncut).
    ops: Vec<Op>,
    /// Restarts that found the old record (or nothing, on a first save).
    old: usize,
    /// Restarts that found the new record.
    new: usize,
}

/// Cuts a save of `new` on `image` at every operation and every part of it; checks each
/// restart.
fn cut_everywhere(image: &[u8], new: &[u8; RECORD_LEN]) -> Found {
    let old = load(image.to_vec()).expect("the starting store loads");
    // The save uncut, to learn its operations.
    let dry = CutFlash::new(image.to_vec(), None);
    FlashStore::new(dry.clone())
        .save(new)
        .expect("an uncut save succeeds");
    let ops = dry.ops();
    assert!(!ops.is_empty());
    let board = gms_core::boards::f405::BOARD;
    let defaults = default_settings();
    let (mut tried, mut found_old, mut found_new) = (0, 0, 0);
    for (index, op) in ops.iter().enumerate() {
        for part in parts(*op) {
            tried += 1;
            let flash = CutFlash::new(image.to_vec(), Some((index, part)));
            let result = FlashStore::new(flash.clone()).save(new);
            assert!(
                result.is_err(),
                "op {index} {op:?} {part:?}: a cut save reports failure"
            );
            // Power back: restart on what the flash holds.
            let after = flash.image();
            let found = load(after.clone());
            let what = format!("cut at op {index}/{} ({op:?}) {part:?}", ops.len());
            match found {
                Ok(f) if f == old => found_old += 1,
                Ok(Some(f)) if f == *new => found_new += 1,
                Ok(_) => panic!("{what}: the restart found neither the old record nor the new one"),
                Err(e) => panic!("{what}: the restart could not read the store: {e:?}"),
            }
            // The start-up decision runs one of the two sets, without a fault.
            let up =
                startup(load(after.clone()), &defaults, &board, &mut |_| {}).expect("defaults run");
            assert_eq!(up.faults, Faults::NONE, "{what}: {}", up.note);
            // And the store takes the next save.
            let next = record(9999);
            let flash = CutFlash::new(after, None);
            let mut store = FlashStore::new(flash);
            store
                .save(&next)
                .unwrap_or_else(|e| panic!("{what}: the next save failed: {e:?}"));
            assert_eq!(
                store.load(),
                Ok(Some(next)),
                "{what}: the next save reads back"
            );
        }
    }
    println!(
        "{} operations, {tried} cuts: {found_old} restarts found the old record, {found_new} \
         the new",
        ops.len()
    );
    // Both outcomes occur: the cuts cover the whole save, from before it began to its end.
    assert!(found_old > 0 && found_new > 0);
    assert!(tried >= ops.len() * 2);
    Found {
        tried,
        ops,
        old: found_old,
        new: found_new,
    }
}

#[test]
fn a_cut_first_save_leaves_nothing_or_the_new_record() {
    let f = cut_everywhere(&vec![0xFF; IMAGE_LEN], &record(1));
    assert_eq!(f.old + f.new, f.tried);
}

#[test]
fn a_cut_save_leaves_the_old_or_the_new_record() {
    let image = filled(3);
    assert_eq!(load(image.clone()), Ok(Some(record(2))));
    let f = cut_everywhere(&image, &record(100));
    assert_eq!(f.old + f.new, f.tried);
}

#[test]
fn a_cut_save_that_erases_a_sector_leaves_the_old_or_the_new_record() {
    // Save until a save erases: the one that fills the store's free sector migrates the record
    // and erases the oldest sector.
    let flash = CutFlash::new(vec![0xFF; IMAGE_LEN], None);
    let mut store = FlashStore::new(flash.clone());
    let mut n = 0;
    let before = loop {
        let image = flash.image();
        let ops_before = flash.ops().len();
        store.save(&record(n)).expect("save on a healthy flash");
        n += 1;
        if flash.ops()[ops_before..]
            .iter()
            .any(|o| matches!(o, Op::Erase))
        {
            break image;
        }
        assert!(n < 10_000, "no save ever erased");
    };
    // One record is 518 bytes: a 128 KiB sector holds a couple of hundred before the erase.
    assert!(n > 150, "erased after only {n} saves");
    drop(store);
    let f = cut_everywhere(&before, &record(n - 1 + 5000));
    assert!(f.ops.iter().any(|o| matches!(o, Op::Erase)));
    assert_eq!(f.old + f.new, f.tried);
    println!("the save after {n} saves erases a sector");
}

/// A firmware update: the store holds records of an older firmware whose table lacked
/// `pos.ki_fric`; the new firmware's first save is cut everywhere. Every restart finds the old
/// record or the new one, and the start-up runs either without a fault: the old one loads
/// under the new table (`pos.ki_fric` at its default), the new one as saved.
#[test]
fn a_cut_first_save_after_an_update_leaves_the_old_firmwares_record_or_the_new() {
    let old_table: Vec<Param> = PARAMS
        .iter()
        .filter(|p| p.path != "pos.ki_fric")
        .copied()
        .collect();
    let flash = CutFlash::new(vec![0xFF; IMAGE_LEN], None);
    let mut store = FlashStore::new(flash.clone());
    let mut old = default_settings();
    old.pid.kp = 0.37;
    old.pid.ki_fric = 0.9;
    store
        .save(&encode_settings_with(&old, &old_table))
        .expect("save on a healthy flash");
    drop(store);
    let image = flash.image();
    let mut lines = Vec::new();
    let up = startup(
        load(image.clone()),
        &default_settings(),
        &gms_core::boards::f405::BOARD,
        &mut |l| lines.push(l),
    )
    .expect("defaults run");
    assert_eq!(up.settings.pid.kp, 0.37);
    assert_eq!(up.settings.pid.ki_fric, default_settings().pid.ki_fric);
    assert_eq!(lines, [ReportLine::Missing("pos.ki_fric")]);
    let f = cut_everywhere(&image, &record(7));
    assert_eq!(f.old + f.new, f.tried);
}

/// A store that keeps a position map too (its buffer leaked: one per store, a test's).
fn map_store(flash: CutFlash) -> FlashStore<CutFlash> {
    use gms_core::device::store::MAP_BUFFER_LEN;
    FlashStore::new(flash).with_map_buffer(Box::leak(vec![0u8; MAP_BUFFER_LEN].into_boxed_slice()))
}

/// A distinct, valid map record number `i`: 512 bins over a revolution.
fn map_record(i: u32) -> Vec<u8> {
    use gms_core::control::posmap::{MAP_RECORD_LEN, MAP_VALUES, encode_map};
    let values: Vec<f32> = (0..MAP_VALUES)
        .map(|k| {
            if k % 2 == 0 {
                1e-6 * ((k + i as usize) % 97) as f32
            } else {
                1.0 + 1e-3 * ((k / 2 + i as usize) % 13) as f32
            }
        })
        .collect();
    let mut rec = vec![0u8; MAP_RECORD_LEN];
    encode_map(std::f32::consts::TAU, 512, &values, &mut rec);
    rec
}

/// The map stored in `store`, if any.
fn stored_map(store: &mut FlashStore<CutFlash>) -> Option<Vec<u8>> {
    let len = store.load_map().expect("the map loads")?;
    Some(store.map_buffer().unwrap()[..len].to_vec())
}

/// Saves the map `rec` into `store`.
fn save_map(
    store: &mut FlashStore<CutFlash>,
    rec: &[u8],
) -> Result<(), gms_core::device::StoreError> {
    store.map_buffer().unwrap()[..rec.len()].copy_from_slice(rec);
    store.save_map(rec.len())
}

/// The position map beside the parameter record: a save of a new map cut at every write and
/// erase it makes (and parts of each) leaves the old map or the new one, bit for bit, and the
/// parameter record untouched; the start-up's restore then loads the one found for the
/// settings' geometry, and refuses a map of another bin count with its reason.
#[test]
fn a_cut_map_save_leaves_the_old_or_the_new_map_and_the_record() {
    use gms_core::control::posmap::{MAP_VALUES, MapParams};
    use gms_core::device::restore_map as restore;
    // A store with a record and map 1.
    let flash = CutFlash::new(vec![0xFF; IMAGE_LEN], None);
    let mut store = map_store(flash.clone());
    store.save(&record(7)).unwrap();
    save_map(&mut store, &map_record(1)).unwrap();
    drop(store);
    let image = flash.image();
    let (old, new) = (map_record(1), map_record(2));
    // The save uncut, for its operations.
    let dry = CutFlash::new(image.clone(), None);
    save_map(&mut map_store(dry.clone()), &new).unwrap();
    let ops = dry.ops();
    let (mut tried, mut found_old, mut found_new) = (0, 0, 0);
    for (index, op) in ops.iter().enumerate() {
        for part in parts(*op) {
            tried += 1;
            let flash = CutFlash::new(image.clone(), Some((index, part)));
            assert!(save_map(&mut map_store(flash.clone()), &new).is_err());
            let after = flash.image();
            let mut store = map_store(CutFlash::new(after.clone(), None));
            let what = format!("cut at op {index}/{} ({op:?}) {part:?}", ops.len());
            match stored_map(&mut store) {
                Some(m) if m == old => found_old += 1,
                Some(m) if m == new => found_new += 1,
                _ => panic!("{what}: neither the old map nor the new one"),
            }
            assert_eq!(store.load(), Ok(Some(record(7))), "{what}: the record");
            // The start-up restores it for a revolution of 512 bins.
            let mut table = vec![0.0f32; MAP_VALUES];
            let p = MapParams {
                enable: 1.0,
                ..MapParams::DEFAULT
            };
            assert_eq!(restore(&mut store, &p, &mut table), Ok(true), "{what}");
        }
    }
    println!(
        "map save: {} operations, {tried} cuts: {found_old} restarts found the old map, \
         {found_new} the new",
        ops.len()
    );
    // Every cut left one of the two (the save commits the new item with its last write, so
    // a cut within it leaves the old); the save uncut leaves the new one.
    assert_eq!(found_old + found_new, tried);
    assert!(found_old > 0);
    assert_eq!(
        stored_map(&mut map_store(CutFlash::new(dry.image(), None))),
        Some(new.clone())
    );
    // A map of another bin count than the settings': refused with the reason, the table
    // left with no effect.
    let mut store = map_store(CutFlash::new(image, None));
    let mut table = vec![7.0f32; MAP_VALUES];
    let p = MapParams {
        bins: 256.0,
        ..MapParams::DEFAULT
    };
    let r = restore(&mut store, &p, &mut table);
    assert_eq!(
        r,
        Err("stored map: another period or bin count than map.period and map.bins")
    );
    assert!(table.chunks(2).all(|c| c[0] == 0.0 && c[1] == 1.0));
}
