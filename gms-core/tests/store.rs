//! Power-cut safety of the parameter store (`gms_core::store::FlashStore`): a `save` is cut at
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
use gms_core::device::{ParamStore, default_settings, startup};
use gms_core::drive::{Faults, RECORD_LEN, encode_settings};
use gms_core::protocol::Settings;
use gms_core::store::{FlashStore, SECTOR_SIZE, STORE_RANGE, WORD_SIZE};

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
            let up = startup(load(after.clone()), &defaults, &board).expect("defaults run");
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
    // One record is 266 bytes: a 128 KiB sector holds several hundred before the erase.
    assert!(n > 300, "erased after only {n} saves");
    drop(store);
    let f = cut_everywhere(&before, &record(n - 1 + 5000));
    assert!(f.ops.iter().any(|o| matches!(o, Op::Erase)));
    assert_eq!(f.old + f.new, f.tried);
    println!("the save after {n} saves erases a sector");
}
