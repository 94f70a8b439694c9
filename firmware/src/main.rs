//! gms firmware for the STM32F405 motor driver.
//!
//! Status: skeleton. It links the friction model into a Cortex-M4F image so that the target
//! build is checked from the start; the embassy shell (encoder, PWM, USB, flash) comes with
//! the firmware issue.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use gms_core::{FrictionModel, Gms, presets};
use panic_halt as _;

#[entry]
fn main() -> ! {
    let mut model = match Gms::try_new(presets::table1()) {
        Ok(m) => m,
        Err(_) => loop {
            cortex_m::asm::wfi();
        },
    };
    let mut x = 0.0f32;
    loop {
        // Placeholder load: a slow triangle wave through the model, 10 kHz steps.
        let dx = if (x as u32 / 4) % 2 == 0 { 1e-6 } else { -1e-6 };
        x += 1.0;
        let f = model.advance(dx, 1e-4);
        cortex_m::asm::delay(f.to_bits() & 1);
    }
}
