//! The shipped firmware image on an emulated STM32F4: the ELF that `cargo fw` / `cargo
//! fw-f446` builds, run from its reset vector on unicorn's Cortex-M4F (Thumb-2 and the FPU)
//! with register models of the peripherals it touches, written from the reference manuals
//! (RM0090 for the F405, RM0390 for the F446; the core's registers from the ARMv7-M ARM and
//! PM0214), its control loop closed on hil-sim's plant.
//!
//! - [`machine`]: the emulated core: memory, exception entry and return (the NVIC's
//!   priorities, BASEPRI/PRIMASK, the extended FP frame), time, the run loop, the records
//!   (instructions per interrupt, the deepest stack, PRIMASK held).
//! - [`core_regs`]: the core's memory-mapped registers (SCB, NVIC, MPU, DWT, SysTick, DBGMCU).
//! - [`periph`]: the chip's peripherals (RCC, PWR, FLASH, IWDG, GPIO, timers, ADC, DMA,
//!   USART), each a register model with tests of its own.
//! - [`rtt`]: the defmt log, read from the image's RTT buffer and decoded.
//!
//! unicorn is GPL-2.0: this crate is a test tool and is not published; nothing else in the
//! workspace depends on it.

pub mod core_regs;
pub mod cycles;
pub mod machine;
pub mod periph;
pub mod rtt;

pub use machine::{Board, Machine, Options, TimeModel};
