//! The clock-tree and memory-map arithmetic of `gms_core::boards::hw` against hand-worked figures.

use gms_core::boards::hw::{F4Clocks, F405_LIMITS, F446_LIMITS, MemoryMap};

/// 8 MHz HSE, M 4, N 168, P 2, Q 7; AHB 1, APB1 4, APB2 2.
const CLK: F4Clocks = F4Clocks {
    hse_hz: 8_000_000,
    hse_bypass: false,
    pll_m: 4,
    pll_n: 168,
    pll_p: 2,
    pll_q: 7,
    ahb_div: 1,
    apb1_div: 4,
    apb2_div: 2,
};

#[test]
fn the_168_mhz_tree() {
    assert_eq!(CLK.pll_in_hz(), 2_000_000);
    assert_eq!(CLK.vco_hz(), 336_000_000);
    assert_eq!(CLK.sysclk_hz(), 168_000_000);
    assert_eq!(CLK.usb_hz(), 48_000_000);
    assert_eq!(CLK.hclk_hz(), 168_000_000);
    assert_eq!(CLK.pclk1_hz(), 42_000_000);
    assert_eq!(CLK.pclk2_hz(), 84_000_000);
    // Timers on a divided APB run at twice its clock.
    assert_eq!(CLK.tim_apb1_hz(), 84_000_000);
    assert_eq!(CLK.tim_apb2_hz(), 168_000_000);
    // embassy: (84 MHz - 1) / 36 MHz = 2: prescaler 4.
    assert_eq!(CLK.adc_hz(), 21_000_000);
    assert_eq!(CLK.check(&F405_LIMITS), Ok(()));
    assert_eq!(CLK.check(&F446_LIMITS), Ok(()));
}

#[test]
fn trees_outside_the_limits_are_named() {
    let fast = F4Clocks {
        pll_n: 180,
        pll_q: 8,
        ..CLK
    }; // 180 MHz, USB 45 MHz
    assert_eq!(
        fast.check(&F405_LIMITS),
        Err("USB clock not exactly 48 MHz")
    );
    let usb_ok = F4Clocks {
        pll_n: 192,
        pll_p: 2,
        pll_q: 8,
        ..CLK
    }; // 192 MHz
    assert_eq!(
        usb_ok.check(&F446_LIMITS),
        Err("SYSCLK above the part's maximum")
    );
    let apb1 = F4Clocks { apb1_div: 2, ..CLK }; // 84 MHz APB1
    assert_eq!(
        apb1.check(&F405_LIMITS),
        Err("APB1 above the part's maximum")
    );
    assert_eq!(apb1.tim_apb1_hz(), 168_000_000);
    let undivided = F4Clocks {
        apb2_div: 1,
        ahb_div: 2,
        ..CLK
    }; // HCLK 84, APB2 84 (x1)
    assert_eq!(undivided.tim_apb2_hz(), 84_000_000);
    let pll_in = F4Clocks { pll_m: 8, ..CLK }; // 1 MHz: allowed
    assert_eq!(pll_in.pll_in_hz(), 1_000_000);
    let slow_in = F4Clocks { pll_m: 16, ..CLK }; // 0.5 MHz
    assert_eq!(
        slow_in.check(&F405_LIMITS),
        Err("PLL input outside 1-2 MHz")
    );
    let p3 = F4Clocks { pll_p: 3, ..CLK };
    assert_eq!(p3.check(&F405_LIMITS), Err("PLL P not 2, 4, 6 or 8"));
    // ADC prescalers: 60 MHz -> 4 (15 MHz); 36 MHz -> 2 (18 MHz); 288 MHz would be beyond 8.
    let a60 = F4Clocks {
        pll_n: 120,
        pll_q: 5,
        apb2_div: 1,
        ..CLK
    }; // VCO 240, SYS 120, APB2 120?
    assert_eq!(a60.pclk2_hz(), 120_000_000);
    // (120 MHz - 1) / 36 MHz = 3: prescaler 4.
    assert_eq!(a60.adc_hz(), 30_000_000);
}

#[test]
fn memory_maps() {
    // The F405: 1 MiB, firmware in the first 768 KiB, the store in sectors 10-11.
    let f405 = MemoryMap {
        flash_len: 1024 * 1024,
        app_len: 768 * 1024,
        ram_len: 128 * 1024,
        store: 0xC_0000..0x10_0000,
        store_sector: 128 * 1024,
    };
    assert_eq!(f405.check(), Ok(()));
    let overlap = MemoryMap {
        app_len: 800 * 1024,
        ..f405.clone()
    };
    assert_eq!(
        overlap.check(),
        Err("the firmware's flash overlaps the store")
    );
    let beyond = MemoryMap {
        store: 0xE_0000..0x12_0000,
        app_len: 0xE_0000,
        ..f405.clone()
    };
    assert_eq!(beyond.check(), Err("the store ends beyond the flash"));
    let one = MemoryMap {
        store: 0xE_0000..0x10_0000,
        ..f405.clone()
    };
    assert_eq!(one.check(), Err("the store needs two sectors or more"));
    let odd = MemoryMap {
        store: 0xC_1000..0x10_0000,
        ..f405
    };
    assert_eq!(odd.check(), Err("the store is not whole sectors"));
}
