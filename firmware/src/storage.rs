//! The parameter store: gms-core's [`FlashStore`] (one record under one key of a
//! sequential-storage map in the last two 128 KiB flash sectors) on the internal flash.
//!
//! The F405 has one flash bank: an erase or a write stalls every instruction fetch from flash,
//! the control interrupt and every task included. The device core therefore saves only while
//! the bridge is off (the PWM outputs are then low whatever the CPU does), and [`StoreFlash`]
//! keeps an erase inside the watchdog:
//!
//! - embassy-stm32 0.6 erases with FLASH_CR.PSIZE as it finds it (`flash/f4.rs`:
//!   `blocking_erase_sector` only *modifies* CR; its writes leave PSIZE at 0 afterwards), i.e.
//!   at ×8 parallelism, up to 4 s per 128 KiB sector (DS8626 table "Flash memory programming",
//!   t_ERASE128KB: ×8 typ 2 s / max 4 s, ×32 typ 1 s / max 2 s). [`StoreFlash`] sets ×32
//!   (allowed from 2.7 V, RM0090 §3.6.2 table 9) before each sector erase: at most 2 s.
//! - The independent watchdog runs at 4 s nominal on the LSI, 2.72 s if the LSI runs at its
//!   47 kHz maximum (DS8626 LSI table: 17-47 kHz). Nothing can feed it during an erase, so
//!   [`StoreFlash`] reloads it right before each sector erase: 2 s of erase leave 0.7 s.
//! - The data cache may hold lines of the store read before an erase or a write; it is
//!   flushed after each (ST's HAL does this after an erase, `FLASH_FlushCaches`).
//!
//! A save erases at most one sector in the normal course (`gms-core/tests/store.rs`: the save
//! that fills a sector erases the other); a repair may erase both, each with its own reload.
//! The protocol gives a `save` [`gms_core::protocol::SAVE_REPLY_MS`] to answer.

use embassy_embedded_hal::adapter::BlockingAsync;
use embassy_stm32::flash::{Blocking, Error, Flash, MAX_ERASE_SIZE, WRITE_SIZE};
use embassy_stm32::pac;
use embedded_storage::nor_flash::{ErrorType, NorFlash, ReadNorFlash};
use gms_core::device::store::{FlashStore, SECTOR_SIZE, WORD_SIZE};

use crate::board::MEMORY;

/// Longest erase of one 128 KiB sector at ×32 parallelism \[ms\] (DS8626).
pub const SECTOR_ERASE_MAX_MS: u32 = 2000;

// Two sector erases (a repair) and the record's writes fit the protocol's reply time.
const _: () = assert!(2 * SECTOR_ERASE_MAX_MS + 500 <= gms_core::protocol::SAVE_REPLY_MS);
// An erase fits the watchdog at the LSI's fastest (47 kHz against the nominal 32 kHz).
const _: () =
    assert!((SECTOR_ERASE_MAX_MS as u64) * 1000 * 47 < crate::board::WATCHDOG_US as u64 * 32);

/// The internal flash as the store uses it (see the module's notes).
pub struct StoreFlash(Flash<'static, Blocking>);

/// Reloads the independent watchdog (IWDG_KR = 0xAAAA, RM0090 §19.4.1), as
/// `IndependentWatchdog::pet` does; harmless if it is not started.
fn reload_watchdog() {
    pac::IWDG
        .kr()
        .write(|w| w.set_key(pac::iwdg::vals::Key::RESET));
}

/// Flushes the flash data cache (`f4_regs::clock::flush_data_cache`).
fn flush_data_cache() {
    f4_regs::clock::flush_data_cache(pac::FLASH);
}

/// Sets FLASH_CR.PSIZE to ×32 for the next erase, unlocking CR first if it is locked
/// (`f4_regs::clock::erase_at_x32`: embassy's erase then finds CR unlocked, keeps PSIZE and
/// locks CR again when done).
fn psize_x32() {
    f4_regs::clock::erase_at_x32(pac::FLASH);
}

impl ErrorType for StoreFlash {
    type Error = Error;
}

impl ReadNorFlash for StoreFlash {
    const READ_SIZE: usize = <Flash<'static, Blocking> as ReadNorFlash>::READ_SIZE;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Error> {
        self.0.read(offset, bytes)
    }

    fn capacity(&self) -> usize {
        self.0.capacity()
    }
}

impl NorFlash for StoreFlash {
    const WRITE_SIZE: usize = WRITE_SIZE;
    const ERASE_SIZE: usize = MAX_ERASE_SIZE;

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Error> {
        let r = self.0.write(offset, bytes);
        flush_data_cache();
        r
    }

    /// Sector by sector, each at ×32 and with the watchdog reloaded just before.
    fn erase(&mut self, from: u32, to: u32) -> Result<(), Error> {
        let sector = SECTOR_SIZE as u32;
        if !from.is_multiple_of(sector) || !to.is_multiple_of(sector) || to < from {
            return Err(Error::Unaligned);
        }
        let mut at = from;
        while at < to {
            reload_watchdog();
            psize_x32();
            let r = self.0.erase(at, at + SECTOR_SIZE as u32);
            flush_data_cache();
            r?;
            at += SECTOR_SIZE as u32;
        }
        Ok(())
    }
}

/// The parameter store on the internal flash.
pub type Store = FlashStore<BlockingAsync<StoreFlash>>;

// The store's format assumes the F4's flash geometry as embassy-stm32 reports it, and the
// board's store sectors are of that size.
const _: () = assert!(WRITE_SIZE == WORD_SIZE && MAX_ERASE_SIZE == SECTOR_SIZE);
const _: () = assert!(MEMORY.store_sector as usize == SECTOR_SIZE);

/// The store on the internal flash.
pub fn new(flash: Flash<'static, Blocking>) -> Store {
    FlashStore::with_range(BlockingAsync::new(StoreFlash(flash)), MEMORY.store.clone())
}
