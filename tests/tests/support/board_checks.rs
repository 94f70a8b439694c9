//! The checks every board description passes (gms-core's `boards`), shared by the `board_*`
//! test targets, one per board.

use gms_core::boards::hw::{F4Clocks, F4Limits, MemoryMap};
use gms_core::device::store::SECTOR_SIZE;
use gms_core::device::{Board, default_settings, prepare};
use gms_core::drive::{self, SenseTiming};

/// One board's description, as its files give it.
pub struct Desc {
    pub name: &'static str,
    pub clocks: F4Clocks,
    pub part: F4Limits,
    pub memory: MemoryMap,
    pub timing: SenseTiming,
    pub board: Board,
    pub chip: &'static str,
    pub encoder_max_rate: f32,
    pub watchdog_us: u32,
    /// The power stage's shunt × amplifier gain \[V/A\].
    pub sense_v_per_a: f32,
}

/// Clock tree within the part's limits, memory map whole, the store's sectors the format's.
pub fn clocks_and_memory(d: &Desc) {
    assert_eq!(d.clocks.check(&d.part), Ok(()), "{}", d.name);
    assert_eq!(d.memory.check(), Ok(()), "{}", d.name);
    assert_eq!(d.memory.store_sector as usize, SECTOR_SIZE, "{}", d.name);
    // CI's firmware budget is 160 KiB of flash, 96 KiB of RAM: the board must have them.
    assert!(d.memory.app_len >= 160 * 1024, "{}", d.name);
    assert!(d.memory.ram_len >= 96 * 1024, "{}", d.name);
    assert!(d.chip.starts_with("STM32F4"), "{}", d.name);
}

/// The device core's view of the board follows from the clock tree, not from numbers typed
/// twice.
pub fn device_view(d: &Desc) {
    let b = d.board;
    // The DWT counts HCLK; TIM8 is on APB2, its clock doubled when APB2 is divided.
    assert_eq!(b.limits.clock_hz, d.clocks.hclk_hz(), "{}", d.name);
    assert_eq!(b.pwm_timer_hz, d.clocks.tim_apb2_hz(), "{}", d.name);
    assert_eq!(b.sense_oversample, d.timing.conversions, "{}", d.name);
    assert_eq!(b.sense.window_s, d.timing.window_s(), "{}", d.name);
    assert_eq!(d.timing.adc_hz, d.clocks.adc_hz(), "{}", d.name);
    assert!(d.timing.adc_hz <= 36_000_000, "{}", d.name);
    // The device's default `sense.v_per_a` is the power stage as built: 68 mohm × 50 shows
    // ±0.426 A around the 1.65 V zero within the INA240's linear range (2047 codes of
    // 0.237 mA to the top rail, less the 0.2 V, 248 codes, the amplifier does not reach).
    let s = default_settings();
    assert_eq!(s.sense_v_per_a, d.sense_v_per_a, "{}", d.name);
    let range = b.sense.range(s.sense_v_per_a);
    let expect = (2047.0 - 0.2 / 3.3 * 4095.0) * (3.3 / 4095.0 / 3.4);
    assert!((range - expect).abs() < 1e-4, "{}: {range}", d.name);
    assert!((range - 0.4264).abs() < 1e-4, "{}: {range}", d.name);
    // The encoder filter for the board's timer clock passes the design rate.
    let (code, window) = drive::encoder_filter(d.clocks.tim_apb1_hz(), d.encoder_max_rate);
    assert!(code > 0 && window <= 0.5 / d.encoder_max_rate, "{}", d.name);
}

/// The default parameter set runs at 20 kHz and the sense window is centred with room for the
/// step.
pub fn default_set_and_sense(d: &Desc) {
    let a = prepare(&default_settings(), &d.board).unwrap_or_else(|e| panic!("{}: {e}", d.name));
    let period = 1.0 / default_settings().cur_rate_hz;
    let counts = d.board.pwm_timer_hz as f32 / (a.psc + 1) as f32;
    assert!(
        (2.0 * a.arr as f32 / counts - period).abs() < 1e-3 * period,
        "{}",
        d.name
    );
    // The trigger's lead fits the half period, and the samples are in early enough to leave
    // the step its budget before the next bottom.
    let lead = d.timing.lead_counts(d.board.pwm_timer_hz, a.psc);
    assert!(lead > 0 && lead < a.arr, "{}", d.name);
    let after_bottom = d.timing.window_s() - d.timing.lead_s();
    assert!(
        after_bottom + d.board.limits.budget_fraction * period < period,
        "{}",
        d.name
    );
}

/// A sector erase fits the watchdog at the LSI's fastest, two of them the protocol's save
/// time.
pub fn erase_within_watchdog(d: &Desc) {
    // A 128 KiB sector at ×32 erases in 2 s at most; the watchdog's timeout is set at the
    // LSI's nominal 32 kHz, and is shorter by 32/47 at its 47 kHz maximum.
    let worst = d.watchdog_us as f64 * 1e-6 * 32.0 / 47.0;
    assert!(worst > 2.0 + 0.25, "{}: {worst}", d.name);
    assert!(2.0 * 2.0 + 0.5 <= gms_core::protocol::SAVE_REPLY_MS as f64 / 1000.0);
}

/// Every check.
pub fn all(d: &Desc) {
    clocks_and_memory(d);
    device_view(d);
    default_set_and_sense(d);
    erase_within_watchdog(d);
}
