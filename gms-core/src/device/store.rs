//! The parameter store on NOR flash, one format for the board and the virtual device: one
//! record ([`crate::device::encode_settings`]: version, each setting under its id, CRC-32) under one
//! key of a `sequential-storage` map over two or more flash sectors ([`STORE_RANGE`] on the
//! F405 board and in the simulator's store image; each board says where). The firmware runs it on the
//! STM32F405's internal flash; `hil-sim serve --store FILE` on a file holding the image of the
//! same range (same word and sector sizes), so that a store written by one is read by the
//! other.
//!
//! Power cuts: sequential-storage writes a new item completely before the old one stops
//! counting, so a cut during `save` leaves the old or the new record, never a mix
//! (`gms-core/tests/store.rs` cuts the flash at every write and erase of a save).

use core::future::Future;
use core::pin::pin;
use core::task::{Context, Poll, Waker};

use embedded_storage_async::nor_flash::NorFlash;
use sequential_storage::cache::{Cache, Uncached};
use sequential_storage::map::{MapConfig, MapStorage};

use crate::device::RECORD_LEN;
use crate::device::{ParamStore, StoreError};

/// The store's flash range, as offsets from the start of the F405's flash: its last two
/// 128 KiB sectors (10 and 11, RM0090 table 5), which `memory.x` leaves out of FLASH.
pub const STORE_RANGE: core::ops::Range<u32> = 0x000C_0000..0x0010_0000;
/// Flash word of the F405 as embassy-stm32 0.6 writes it (`WRITE_SIZE`) \[bytes\].
pub const WORD_SIZE: usize = 4;
/// Sector size of the store's range (`MAX_ERASE_SIZE` of embassy-stm32 0.6 for the F405)
/// \[bytes\].
pub const SECTOR_SIZE: usize = 128 * 1024;

/// The key of the parameter record.
const KEY: u8 = 1;

/// The key of the position map's record.
const KEY_MAP: u8 = 2;

/// The bytes a map buffer needs ([`FlashStore::with_map_buffer`]): the record, and a scratch
/// area for the storage layer (the record, its key and alignment).
pub const MAP_BUFFER_LEN: usize = 2 * (crate::control::posmap::MAP_RECORD_LEN + 32);

/// The buffer holds one record plus sequential-storage's key and alignment.
const BUF: usize = RECORD_LEN + 32;

type Map<F> = MapStorage<u8, F, Cache<Uncached, Uncached, Uncached, u8>>;

/// Runs a future whose work is synchronous underneath (a blocking flash behind the async
/// traits) to completion.
fn block_on<T>(fut: impl Future<Output = T>) -> T {
    let mut fut = pin!(fut);
    let mut cx = Context::from_waker(Waker::noop());
    loop {
        if let Poll::Ready(v) = fut.as_mut().poll(&mut cx) {
            return v;
        }
    }
}

/// The parameter store over a NOR flash `F`.
pub struct FlashStore<F: NorFlash> {
    map: Option<Map<F>>,
    buf: [u8; BUF],
    /// The position map's record and scratch ([`MAP_BUFFER_LEN`] bytes), if given.
    map_buf: Option<&'static mut [u8]>,
}

impl<F: NorFlash> FlashStore<F> {
    /// A store on `flash` over [`STORE_RANGE`] (the F405's sectors 10-11; the simulator's
    /// image).
    pub fn new(flash: F) -> Self {
        Self::with_range(flash, STORE_RANGE)
    }

    /// A store on `flash` over `range` (offsets from the flash start). A range that is not
    /// whole sectors of `flash` gives a store whose every operation fails.
    pub fn with_range(flash: F, range: core::ops::Range<u32>) -> Self {
        let map = MapConfig::<F>::try_new(range)
            .ok()
            .map(|c| MapStorage::new(flash, c, Cache::new_uncached()));
        FlashStore {
            map,
            buf: [0; BUF],
            map_buf: None,
        }
    }

    /// The store keeps a position map too, in `buf` ([`MAP_BUFFER_LEN`] bytes at least: a
    /// static on the board, out of the stack).
    pub fn with_map_buffer(mut self, buf: &'static mut [u8]) -> Self {
        self.map_buf = (buf.len() >= MAP_BUFFER_LEN).then_some(buf);
        self
    }

    /// The flash back (to inspect it, or to restart on it).
    pub fn into_flash(self) -> Option<F> {
        self.map.map(|m| m.destroy().0)
    }
}

impl<F: NorFlash> FlashStore<F> {
    /// The storage layer and its scratch buffer: the map buffer's scratch half when there is
    /// one (a fetch reads past every item on its way, and a map's is larger than the record's
    /// buffer), else the record's.
    fn parts(&mut self) -> Result<(&mut Map<F>, &mut [u8]), StoreError> {
        let FlashStore { map, buf, map_buf } = self;
        let map = map.as_mut().ok_or(StoreError::Flash)?;
        let scratch: &mut [u8] = match map_buf.as_deref_mut() {
            Some(m) => m.get_mut(MAP_BUFFER_LEN / 2..).ok_or(StoreError::Length)?,
            None => buf,
        };
        Ok((map, scratch))
    }
}

impl<F: NorFlash> ParamStore for FlashStore<F> {
    // Not inlined: the record's copy in this frame, not in the caller's task frame (a task's
    // frame must step the stack by less than the board's guard: `cargo xtask check-elf`).
    #[inline(never)]
    fn load(&mut self) -> Result<Option<[u8; RECORD_LEN]>, StoreError> {
        let (map, scratch) = self.parts()?;
        let item: Option<&[u8]> =
            block_on(map.fetch_item(scratch, &KEY)).map_err(|_| StoreError::Flash)?;
        let Some(bytes) = item else {
            return Ok(None);
        };
        // A record of an earlier version may be shorter: zero-padded, as the decoder reads it.
        let mut rec = [0u8; RECORD_LEN];
        if bytes.len() > RECORD_LEN {
            return Err(StoreError::Length);
        }
        for (d, s) in rec.iter_mut().zip(bytes) {
            *d = *s;
        }
        Ok(Some(rec))
    }

    // Not inlined, as `load`.
    #[inline(never)]
    fn save(&mut self, rec: &[u8; RECORD_LEN]) -> Result<(), StoreError> {
        let (map, scratch) = self.parts()?;
        let value: &[u8] = rec;
        block_on(map.store_item(scratch, &KEY, &value)).map_err(|_| StoreError::Flash)
    }

    fn map_buffer(&mut self) -> Option<&mut [u8]> {
        let buf = self.map_buf.as_deref_mut()?;
        buf.get_mut(..MAP_BUFFER_LEN / 2)
    }

    fn save_map(&mut self, len: usize) -> Result<(), StoreError> {
        let map = self.map.as_mut().ok_or(StoreError::Flash)?;
        let buf = self.map_buf.as_deref_mut().ok_or(StoreError::Flash)?;
        let (rec, scratch) = buf
            .split_at_mut_checked(MAP_BUFFER_LEN / 2)
            .ok_or(StoreError::Length)?;
        let value: &[u8] = rec.get(..len).ok_or(StoreError::Length)?;
        block_on(map.store_item(scratch, &KEY_MAP, &value)).map_err(|_| StoreError::Flash)
    }

    fn load_map(&mut self) -> Result<Option<usize>, StoreError> {
        let map = self.map.as_mut().ok_or(StoreError::Flash)?;
        let Some(buf) = self.map_buf.as_deref_mut() else {
            return Ok(None);
        };
        let (rec, scratch) = buf
            .split_at_mut_checked(MAP_BUFFER_LEN / 2)
            .ok_or(StoreError::Length)?;
        let item: Option<&[u8]> =
            block_on(map.fetch_item(scratch, &KEY_MAP)).map_err(|_| StoreError::Flash)?;
        let Some(bytes) = item else {
            return Ok(None);
        };
        if bytes.len() > rec.len() {
            return Err(StoreError::Length);
        }
        for (d, s) in rec.iter_mut().zip(bytes) {
            *d = *s;
        }
        Ok(Some(bytes.len()))
    }
}
