//! The bench command protocol: line-based ASCII, typable in any serial terminal, shared by
//! the firmware (USB CDC-ACM) and the simulator's virtual device. No allocation.
//!
//! One request per line (LF or CRLF). Every reply ends with one line that starts with `ok`
//! or `err <code> <reason>`; telemetry lines start with `#` so they never mix with replies.
//!
//! | request | reply |
//! |---|---|
//! | `help` | the commands, then `ok` |
//! | `list` | `PATH VALUE UNIT [MIN, MAX]` per parameter, then `ok` |
//! | `get PATH` | `ok VALUE` |
//! | `set PATH VALUE` | `ok`, or `err` (nothing changes) |
//! | `save`, `load`, `defaults` | `ok` or `err` |
//! | `enable`, `disable`, `status`, `clear` | `ok …` or `err` |
//! | `move POS [VEL]` | `ok` or `err` (rad, rad/s) |
//! | `current AMPS` | `ok` or `err`: hold a current (A), the position loop off |
//! | `velocity VEL [AMP F0 F1 SECONDS]` | `ok` or `err`: a constant speed (rad/s), or a sweep around it (rad/s, Hz, Hz, s) |
//! | `hold` | `ok` or `err`: back to position control, stopping where the axis can |
//! | `stream FIELDS RATE_HZ`, `stream off` | `ok` or `err` |
//! | `frf current\|position F_HZ AMP PERIODS SETTLE` | `ok` or `err`: a frequency-response measurement (Hz, A or rad, periods) |
//! | `frf` | `ok state=… inj=… f_hz=… amp=… groups=… in=RE,IM cmd=RE,IM cur=RE,IM pos=RE,IM coh=…` |
//! | `frf off` | `ok`: the measurement stops |
//! | `map read START COUNT`, `map write START OFFSET,SCALE …`, `map clear` | the position map's table |
//! | `table …` | the table motion: `ref`/`corr START V …`, `corr off`, `set POINTS STEPS ORIGIN`, `use`, `run PERIODS`, `stop`, `read ref\|corr\|err START COUNT`, `clear`; `table`: `ok state=… period=… done=… rms=… peak=…` |
//!
//! - `reader`: [`LineReader`] (bytes to lines).
//! - `ring`: [`RingWatch`] (a receive ring filled by circular DMA, checked for laps).
//! - `command`: [`parse`] (a line to a [`Command`]), [`ErrorCode`].
//! - `params`: [`PARAMS`] (the one parameter table: each path's field in the settings; its units
//!   and ranges from the leaf [`crate::settings`]), [`with_value`].
//! - `exec`: [`Device`] (what a device offers), [`execute`] (a line to its reply).
//! - `reply`: [`Reply`] (a reply's last line, `ok …` or `err CODE REASON`, written and read).
//! - `replies`: the replies that carry data ([`CaptureStatus`], [`FrfStatus`],
//!   [`TableStatus`], [`ListRow`], rows and telemetry), each written and read by one type.

use core::fmt::{self, Write};

use crate::control::controller::FfMode;
use crate::numtext::Num;

mod command;
mod exec;
mod params;
mod reader;
mod replies;
mod reply;
mod ring;
mod status;

pub use command::*;
pub use exec::*;
pub use params::*;
pub use reader::*;
pub use replies::*;
pub use reply::*;
pub use ring::*;
pub use status::*;

/// The friction modes as `list` prints their range.
pub const MODE_NAMES: &str = "none, static, gms, gms-adaptive";

/// How long a device may take to answer `save` \[ms\]: a board's flash erases a sector during a
/// save (up to 2 s on the STM32F405, two when the store repairs itself), and answers nothing
/// meanwhile. Other requests are answered within a position period or two.
pub const SAVE_REPLY_MS: u32 = 5000;

/// The baud rate of a board whose link is a UART (the NUCLEO-F446RE's USART2 to the ST-LINK's
/// virtual COM port), 8N1; the host opens every serial port at it (a USB CDC-ACM port ignores
/// it). 921600 baud carries about 92 kB/s: telemetry lines the link cannot carry are dropped
/// on the device, never queued.
pub const UART_BAUD: u32 = 921_600;
