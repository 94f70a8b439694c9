//! The parameter store: gms-core's [`FlashStore`] (one record under one key of a
//! sequential-storage map in the last two 128 KiB flash sectors) on the internal flash.
//!
//! The F405 has one flash bank: an erase or a write stalls every instruction fetch from flash,
//! the control interrupt included, for up to about 2 s. The device core therefore saves only
//! while the bridge is off (the PWM outputs are then low whatever the CPU does).

use embassy_embedded_hal::adapter::BlockingAsync;
use embassy_stm32::flash::{Blocking, Flash, MAX_ERASE_SIZE, WRITE_SIZE};
use gms_core::store::{FlashStore, SECTOR_SIZE, WORD_SIZE};

/// The parameter store on the internal flash.
pub type Store = FlashStore<BlockingAsync<Flash<'static, Blocking>>>;

// The store's format assumes the F405's flash geometry as embassy-stm32 reports it.
const _: () = assert!(WRITE_SIZE == WORD_SIZE && MAX_ERASE_SIZE == SECTOR_SIZE);

/// The store on the internal flash.
pub fn new(flash: Flash<'static, Blocking>) -> Store {
    FlashStore::new(BlockingAsync::new(flash))
}
