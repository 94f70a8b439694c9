//! The register-level shell of the STM32F4 boards: every raw register access the firmware
//! makes itself (rather than through embassy-stm32's drivers), each taking its register blocks
//! as arguments. The firmware passes the chip's blocks (`stm32_metapac::TIM8`, …); the host
//! tests (`tests/`) pass blocks laid on plain memory and read the fields back, and drive the
//! algorithms that wait on the hardware (the update alignment, the bounded waits) through
//! models of it. `no_std`; the decisions stay in gms-core.
//!
//! - [`sense`]: the current-sense chain (ADC1's sequence on TIM8's trigger, DMA2 stream 0
//!   into a buffer), its bounded read for the start-up calibration, its error flags.
//! - [`pwm`]: TIM8 as the bridge's PWM: idle levels, the sense trigger, the compare values and
//!   period, the update event put at the counter's bottom, switching the bridge off.
//! - [`clock`]: the HSE started within a bound, the reset cause, the debug freeze, the flash
//!   accelerator, the flash's erase parallelism and data-cache flush.
//! - [`encoder`]: TIM2's range and input filter.
//! - [`stack`]: the stack's high-water mark from cortex-m-rt's paint.
//! - [`uart_rx`]: a UART's reception by circular DMA, read by the DMA's count (never by the
//!   data register).
//! - [`uart_tx`]: a UART's transmission by DMA, the next batch filled while one is on the line.
//! - [`remap`]: code copied into SRAM1 and run from SRAM1 mapped at 0 (no flash wait
//!   states).
//! - [`mpu`]: the stack guard (an MPU region at the bottom of the stack) and the fault
//!   handlers that run without the stack they overflowed ([`stack_guard_fault_handlers`]).
#![no_std]

pub use stm32_metapac as pac;

pub mod clock;
mod dma;
pub mod encoder;
pub mod mpu;
pub mod pwm;
pub mod remap;
pub mod sense;
pub mod stack;
pub mod uart_rx;
pub mod uart_tx;
