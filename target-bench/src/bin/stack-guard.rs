//! The stack guard on an emulated Cortex-M4F (QEMU `netduinoplus2`): `f4_regs::mpu`'s guard
//! at the bottom of the stack, its fault handlers, then a recursion that overflows the stack.
//! Prints `stack guard hit: …` and exits with success from the fault handler (which runs on a
//! fresh stack), or exits with failure if the recursion comes back or the guard cannot be
//! placed. `cargo target-bench` runs it.
#![no_std]
#![no_main]

use core::hint::black_box;

use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hprintln};
use f4_regs::mpu::{self, CoreRegs};

f4_regs::stack_guard_fault_handlers!();

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    debug::exit(debug::EXIT_FAILURE);
    loop {
        cortex_m::asm::wfi();
    }
}

unsafe extern "C" {
    static _stack_end: u32;
    static _stack_start: u32;
}

/// The deepest the recursion got (its frames' addresses, written before each call).
static mut DEEPEST: u32 = u32::MAX;

/// The fault handlers' way out: what the fault status registers say (CFSR at 0xE000ED28,
/// HFSR at 0xE000ED2C, MMFAR at 0xE000ED34), then success.
#[unsafe(no_mangle)]
extern "C" fn gms_fault_stop() -> ! {
    // SAFETY: the SCB's fault status registers, read only.
    let (cfsr, hfsr, mmfar) = unsafe {
        (
            core::ptr::read_volatile(0xE000_ED28 as *const u32),
            core::ptr::read_volatile(0xE000_ED2C as *const u32),
            core::ptr::read_volatile(0xE000_ED34 as *const u32),
        )
    };
    // SAFETY: read after the recursion stopped; nothing else writes it.
    let deepest = unsafe { core::ptr::read_volatile(&raw const DEEPEST) };
    hprintln!(
        "stack guard hit: CFSR {:#010x} HFSR {:#010x} MMFAR {:#010x}, deepest frame at {:#010x}",
        cfsr,
        hfsr,
        mmfar,
        deepest
    );
    debug::exit(debug::EXIT_SUCCESS);
    loop {
        cortex_m::asm::wfi();
    }
}

/// Recurses `n` deep with 256 bytes of frame each.
#[inline(never)]
fn recurse(n: u32) -> u32 {
    let buf = black_box([n as u8; 256]);
    let here = buf.as_ptr() as usize as u32;
    // SAFETY: single-threaded, no interrupt touches it.
    unsafe {
        if here < DEEPEST {
            core::ptr::write_volatile(&raw mut DEEPEST, here);
        }
    }
    if n == 0 {
        return buf[0] as u32;
    }
    recurse(black_box(n - 1)) + buf[255] as u32
}

#[entry]
fn main() -> ! {
    let (end, start) = (
        core::ptr::addr_of!(_stack_end) as usize as u32,
        core::ptr::addr_of!(_stack_start) as usize as u32,
    );
    let size = gms_core::boards::hw::STACK_GUARD_BYTES;
    let Some((base, left)) = mpu::guard_region(end, start, size, 16 * 1024) else {
        hprintln!(
            "no room for the guard between {:#010x} and {:#010x}",
            end,
            start
        );
        debug::exit(debug::EXIT_FAILURE);
        loop {}
    };
    hprintln!(
        "guard {:#010x}..{:#010x}, {} B of stack above it",
        base,
        base + size,
        left
    );
    // SAFETY: the core's own MPU and SCB; nothing uses the guard's memory.
    unsafe { mpu::enable_stack_guard(CoreRegs::CORE, base, size) };
    // Far more than the stack holds: 256 B a frame and more, 1000 frames.
    let r = recurse(black_box(1000));
    hprintln!("the recursion came back ({}): no fault", r);
    debug::exit(debug::EXIT_FAILURE);
    loop {
        cortex_m::asm::wfi();
    }
}
