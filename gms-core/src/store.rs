//! The parameter store on NOR flash, one format for the board and the virtual device: one
//! record ([`crate::drive::encode_settings`]: version, layout id, values, CRC-32) under one
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

use crate::device::{ParamStore, StoreError};
use crate::drive::RECORD_LEN;

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

/// The buffer holds one record plus sequential-storage's key and alignment.
const BUF: usize = 512;
const _: () = assert!(RECORD_LEN + 16 <= BUF);

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
        FlashStore { map, buf: [0; BUF] }
    }

    /// The flash back (to inspect it, or to restart on it).
    pub fn into_flash(self) -> Option<F> {
        self.map.map(|m| m.destroy().0)
    }
}

impl<F: NorFlash> ParamStore for FlashStore<F> {
    fn load(&mut self) -> Result<Option<[u8; RECORD_LEN]>, StoreError> {
        let map = self.map.as_mut().ok_or(StoreError::Flash)?;
        let item: Option<&[u8]> =
            block_on(map.fetch_item(&mut self.buf, &KEY)).map_err(|_| StoreError::Flash)?;
        let Some(bytes) = item else {
            return Ok(None);
        };
        let mut rec = [0u8; RECORD_LEN];
        if bytes.len() != RECORD_LEN {
            return Err(StoreError::Length);
        }
        rec.copy_from_slice(bytes);
        Ok(Some(rec))
    }

    fn save(&mut self, rec: &[u8; RECORD_LEN]) -> Result<(), StoreError> {
        let map = self.map.as_mut().ok_or(StoreError::Flash)?;
        let value: &[u8] = rec;
        block_on(map.store_item(&mut self.buf, &KEY, &value)).map_err(|_| StoreError::Flash)
    }
}
