//! The parameter store: one record (gms-core's [`drive::encode_settings`]: version, layout id,
//! values, CRC-32) under one key of a `sequential-storage` map in the last two 128 KiB flash
//! sectors. sequential-storage writes a new item before the old one stops counting, so a power
//! cut during `save` leaves the old or the new record, never a mix.
//!
//! The F405 has one flash bank: an erase or a write stalls every instruction fetch from flash,
//! the control interrupt included, for up to about 2 s. The comms side therefore saves only
//! while the bridge is off (the PWM outputs are then low whatever the CPU does).

use embassy_embedded_hal::adapter::BlockingAsync;
use embassy_futures::block_on;
use embassy_stm32::flash::{Blocking, Flash};
use gms_core::drive::RECORD_LEN;
use sequential_storage::cache::{Cache, Uncached};
use sequential_storage::map::{MapConfig, MapStorage};

use crate::board;

type Nor = BlockingAsync<Flash<'static, Blocking>>;
type Map = MapStorage<u8, Nor, Cache<Uncached, Uncached, Uncached, u8>>;

/// The key of the parameter record.
const KEY: u8 = 1;

/// The store's range, checked at compile time (page-aligned, at least two pages).
const CONFIG: MapConfig<Nor> = MapConfig::new(board::STORE_RANGE);

/// Why the store failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum StoreError {
    /// The flash driver or sequential-storage reported an error.
    Flash,
    /// The stored item is not one record long.
    Length,
}

/// The parameter store.
pub struct Store {
    map: Map,
    buf: [u8; 512],
}

impl Store {
    /// A store on the internal flash.
    pub fn new(flash: Flash<'static, Blocking>) -> Store {
        Store {
            map: MapStorage::new(BlockingAsync::new(flash), CONFIG, Cache::new_uncached()),
            buf: [0; 512],
        }
    }

    /// The stored record, `None` if nothing was ever saved.
    pub fn load(&mut self) -> Result<Option<[u8; RECORD_LEN]>, StoreError> {
        let item: Option<&[u8]> =
            block_on(self.map.fetch_item(&mut self.buf, &KEY)).map_err(|_| StoreError::Flash)?;
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

    /// Stores a record (blocks for the flash write, and an erase when a page fills).
    pub fn save(&mut self, rec: &[u8; RECORD_LEN]) -> Result<(), StoreError> {
        let value: &[u8] = rec;
        block_on(self.map.store_item(&mut self.buf, &KEY, &value)).map_err(|_| StoreError::Flash)
    }
}

// The buffer holds one record plus sequential-storage's key and alignment.
const _: () = assert!(RECORD_LEN + 16 <= 512);
