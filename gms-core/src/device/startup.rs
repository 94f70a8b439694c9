//! A device's start-up and what it keeps: the parameter store's interface, the loop's set
//! prepared for a board, the start-up decision (the stored set, or the defaults and why) and
//! the stored position map restored.

use super::{Applied, Board, Ctrl, RECORD_LEN};
use crate::drive::{self, Faults};
use crate::protocol::Settings;

/// Why the parameter store failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StoreError {
    /// The flash (or its file) or the storage layer reported an error.
    Flash,
    /// The stored item is not one record long.
    Length,
}

/// Where the parameter record lives (the board's flash, a file that stands for it).
pub trait ParamStore {
    /// Stores a record, replacing the last (the old one stays valid until the new is whole).
    fn save(&mut self, rec: &[u8; RECORD_LEN]) -> Result<(), StoreError>;
    /// The last record stored, `None` if nothing was ever saved.
    fn load(&mut self) -> Result<Option<[u8; RECORD_LEN]>, StoreError>;
    /// Where a position map's record is put together before [`ParamStore::save_map`] and
    /// found after [`ParamStore::load_map`] (`None`: this store keeps no map).
    fn map_buffer(&mut self) -> Option<&mut [u8]> {
        None
    }
    /// Stores the map record in the first `len` bytes of the map buffer, replacing the last
    /// (the old one stays valid until the new one is whole).
    fn save_map(&mut self, len: usize) -> Result<(), StoreError> {
        let _ = len;
        Err(StoreError::Flash)
    }
    /// The last map record stored, into the map buffer: its length, `None` if none.
    fn load_map(&mut self) -> Result<Option<usize>, StoreError> {
        Ok(None)
    }
}

/// The loop's parameter set for `s` on `board`: the controller, the limits and the PWM timing;
/// the error says why the board cannot run it.
pub fn prepare(s: &Settings, board: &Board) -> Result<Applied, &'static str> {
    let mut ctrl = Ctrl::try_new(*s).map_err(|_| "the parameter set is invalid")?;
    let (psc, arr) = drive::pwm_timing(board.pwm_timer_hz, s.cur_rate_hz, board.pwm_max_arr)
        .ok_or("the board's PWM timer cannot run rate.cur_hz")?;
    let window = board.sense.window_s;
    if window > 0.0 && window > 2.0 * (1.0 - board.limits.budget_fraction) / s.cur_rate_hz {
        return Err("the board's current sense cannot sample at rate.cur_hz");
    }
    let limits = board.limits(s);
    ctrl.set_duty_max(limits.duty_max);
    Ok(Applied {
        ctrl,
        limits,
        psc,
        arr,
    })
}

/// What a device starts with.
#[derive(Debug, Clone)]
pub struct Startup {
    /// The settings that run.
    pub settings: Settings,
    /// The loop's set for them.
    pub applied: Applied,
    /// Faults to latch (`invalid_params` when the stored set could not be used).
    pub faults: Faults,
    /// What happened, for the log.
    pub note: &'static str,
    /// True when the settings came from the store (someone configured this axis and saved);
    /// false on the built-in defaults (the status reply's `configured`).
    pub configured: bool,
}

/// The start-up decision: the stored set if it is valid and the board runs it; the defaults
/// and a latched `invalid_params` fault if a stored set is unreadable, invalid or not
/// runnable; the defaults without a fault if nothing was ever saved. `Err` only if the
/// defaults themselves cannot run on `board`. A record of another firmware's parameter table
/// loads what this one knows; `log` gets a line for each setting it clamped, dropped or left
/// at its default ([`super::LoadReport`]).
// Not inlined: the stored record, the decoded set and the loaded report stay in this frame, out
// of the start-up task's poll frame (a task's frame must step the stack by less than the
// board's guard: `cargo xtask check-elf`).
#[inline(never)]
pub fn startup(
    stored: Result<Option<[u8; RECORD_LEN]>, StoreError>,
    defaults: &Settings,
    board: &Board,
    log: &mut dyn FnMut(super::ReportLine),
) -> Result<Startup, &'static str> {
    let fallback = |faults: Faults, note: &'static str| -> Result<Startup, &'static str> {
        Ok(Startup {
            settings: *defaults,
            applied: prepare(defaults, board)?,
            faults,
            note,
            configured: false,
        })
    };
    match stored {
        Ok(None) => fallback(Faults::NONE, "nothing saved: running the defaults"),
        Err(_) => fallback(
            Faults::INVALID_PARAMS,
            "parameter store unreadable: running the defaults",
        ),
        Ok(Some(rec)) => match super::decode_settings(&rec, defaults) {
            Err(_) => fallback(
                Faults::INVALID_PARAMS,
                "stored parameters invalid: running the defaults",
            ),
            Ok(loaded) => match prepare(&loaded.settings, board) {
                // What the record of another firmware clamped, dropped or left at a default,
                // a line each for the log (once the set runs).
                Ok(applied) if !loaded.report.is_clean() => {
                    loaded.report.lines().for_each(&mut *log);
                    Ok(Startup {
                        settings: loaded.settings,
                        applied,
                        faults: Faults::NONE,
                        note: "parameters loaded from the store (of another firmware: what it \
                               clamped, dropped or left at a default is logged)",
                        configured: true,
                    })
                }
                Ok(applied) => Ok(Startup {
                    settings: loaded.settings,
                    applied,
                    faults: Faults::NONE,
                    note: "parameters loaded from the store",
                    configured: true,
                }),
                Err(_) => fallback(
                    Faults::INVALID_PARAMS,
                    "stored parameters not runnable on this board: running the defaults",
                ),
            },
        },
    }
}

/// The start-up's position map: cleared (no effect), then the stored map if there is one for
/// the settings' geometry. Returns what happened, for the log: `Ok(true)` loaded, `Ok(false)`
/// none stored, `Err` why a stored one was not used (the table stays clear). The firmware's
/// and the virtual device's start-up both call it.
pub fn restore_map<S: ParamStore + ?Sized>(
    store: &mut S,
    p: &crate::control::posmap::MapParams,
    table: &mut [f32],
) -> Result<bool, &'static str> {
    crate::control::posmap::clear(table);
    let len = match store.load_map() {
        Ok(Some(len)) => len,
        Ok(None) => return Ok(false),
        Err(_) => return Err("stored map unreadable"),
    };
    let Some(buf) = store.map_buffer() else {
        return Ok(false);
    };
    let rec = buf.get(..len).ok_or("stored map: wrong length")?;
    crate::control::posmap::decode_map(rec, p, table)
        .map_err(crate::control::posmap::MapRecordError::reason)?;
    Ok(true)
}
