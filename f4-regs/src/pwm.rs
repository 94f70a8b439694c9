//! TIM8 as the bridge's PWM (an advanced timer, centre-aligned): the outputs' idle levels, the
//! sense trigger on channel 4, the compare values and the period, the update event put at
//! the counter's bottom, and the bridge switched off from any context.

use gms_core::drive::{BridgeOff, Deadman};

use crate::pac;

/// TIMx_SR written to clear UIF alone: rc_w0 flags, 1 leaves a flag, 0 clears it; reserved
/// bits stay 0 (TIMx_SR's flags: bits 0-7 and 9-12, RM0090 §17.4.5).
pub const SR_CLEAR_UIF: u32 = 0x1EFE;

/// Off-state when idle: the outputs forced to their idle level, low (OIS1 = OIS2 = 0), whenever
/// MOE is cleared, by software, a debug halt or a panic (OSSI set, RM0090 §17.4.18 TIMx_BDTR,
/// §17.4.2 TIMx_CR2).
pub fn idle_low(tim: pac::timer::TimAdv) {
    tim.bdtr()
        .modify(|w| w.set_ossi(pac::timer::vals::Ossi::IDLE_LEVEL));
    tim.cr2().modify(|w| {
        w.set_ois(0, false);
        w.set_ois(1, false);
    });
}

/// The break input on, for the clock security system alone: a failed HSE clears MOE in
/// hardware, the outputs at their idle level (low, [`idle_low`]) in the same clock, before the
/// NMI's first instruction (RM0090 §7.2.7: the clock failure event goes to TIM1's and TIM8's
/// break inputs; §17.3.12 "Using the break function": BKE enables the break, which clears MOE
/// asynchronously; §17.4.18 TIMx_BDTR). BKP is active high: the break pin (TIM8_BKIN) is not
/// given to the timer (no pin in its alternate function), so the pin's side of the input is
/// inactive low, and only the clock failure can break. AOE stays 0: MOE stays cleared until
/// software sets it, and nothing does (a break is terminal, as the NMI's trip). BIE stays 0:
/// the NMI is the handler.
pub fn break_on_clock_failure(tim: pac::timer::TimAdv) {
    tim.bdtr().modify(|w| {
        w.set_bkp(0, pac::timer::vals::Bkp::ACTIVE_HIGH);
        w.set_aoe(false);
    });
    // A separate write: BKE takes one APB clock to act (TIMx_BDTR's note), after the polarity.
    tim.bdtr().modify(|w| w.set_bke(0, true));
}

/// The sense trigger: channel 4 (no pin) in PWM mode 1, preloaded, so OC4REF is high while
/// the counter is below CCR4 and rises on the way down `lead` counts before the bottom;
/// OC4REF as TRGO (CR2.MMS = 111, RM0090 §17.4.2), the ADC's trigger, once per period.
pub fn sense_trigger(tim: pac::timer::TimAdv, lead: u16) {
    tim.ccmr_output(1).modify(|w| {
        w.set_ocm(1, pac::timer::vals::Ocm::PWM_MODE1);
        w.set_ocpe(1, true);
    });
    tim.ccr(3).write(|w| w.set_ccr(lead));
    tim.cr2()
        .modify(|w| w.set_mms(pac::timer::vals::Mms::COMPARE_OC4));
}

/// The bridge inputs' edges at low speed (OSPEEDR = 00, RM0090 §8.4.3): at 20 kHz nothing
/// needs nanosecond edges, and slower ones ring less on the wires to the bridge.
pub fn low_speed(gpio: pac::gpio::Gpio, pins: [usize; 2]) {
    gpio.ospeedr().modify(|w| {
        for pin in pins {
            w.set_ospeedr(pin, pac::gpio::vals::Ospeedr::LOW_SPEED);
        }
    });
}

/// Counts of the PWM timer before its update event (the bottom, reached counting down) within
/// which the two compare values are not written: the read of the counter, the check and the
/// two stores take about 15 CPU cycles, under 16 counts at any prescaler (TIM8's clock is the
/// CPU's, 168 MHz).
pub const UPDATE_GUARD: u16 = 16;

/// How long [`wait_clear_of_update`] waits at most [reads of the counter]: 16 counts at the
/// slowest prescaler the loop uses pass in far fewer; a stopped counter (a debug halt) ends
/// the wait.
pub const UPDATE_GUARD_SPINS: u32 = 4096;

/// Whether a counter at `cnt`, counting down or not, is within `guard` counts of the update
/// at the bottom.
pub const fn near_update(cnt: u16, counting_down: bool, guard: u16) -> bool {
    counting_down && cnt <= guard
}

/// Waits, at most `max_spins` reads, while the counter is within [`UPDATE_GUARD`] of the
/// update (then it has passed, and the values written next take effect together at the next
/// one). Returns the reads spent waiting.
#[inline(always)]
pub fn wait_clear_of_update(tim: pac::timer::TimAdv, max_spins: u32) -> u32 {
    let mut spins = 0;
    while spins < max_spins {
        let down = tim.cr1().read().dir() == pac::timer::vals::Dir::DOWN;
        let cnt = tim.cnt().read().cnt();
        if !near_update(cnt, down, UPDATE_GUARD) {
            break;
        }
        spins += 1;
    }
    spins
}

/// Writes the two bridge inputs' compare values (preloaded: they take effect at the next
/// update event), clamped to the 16-bit registers — both at the same update: never within
/// [`UPDATE_GUARD`] counts before it, so that no period runs with one new value and one old
/// (the loop writes them early in the period; only a step late by most of a period could
/// meet the update).
#[inline(always)]
pub fn set_bridge(tim: pac::timer::TimAdv, in1: u32, in2: u32) {
    let clamp = |v: u32| v.min(u16::MAX as u32) as u16;
    let _ = wait_clear_of_update(tim, UPDATE_GUARD_SPINS);
    tim.ccr(0).write(|w| w.set_ccr(clamp(in1)));
    tim.ccr(1).write(|w| w.set_ccr(clamp(in2)));
}

/// Where the PWM timer is in its period now, as gms-core's [`gms_core::drive::pwm_phase`]
/// orders it: CNT and CR1.DIR (read-only in centre-aligned mode, RM0090 §17.4.1), two reads
/// of the APB2 timer. The counter is read first: a bottom between the two reads (a count
/// from the way down, the direction from the way up) reads as just after the bottom, so a
/// step that ends there is taken as late, never the other way round (the bridge off when in
/// doubt); a top between them reads a little later than it was, which no check here minds.
#[inline(always)]
pub fn phase(tim: pac::timer::TimAdv) -> u32 {
    let cnt = tim.cnt().read().cnt();
    let down = tim.cr1().read().dir() == pac::timer::vals::Dir::DOWN;
    gms_core::drive::pwm_phase(cnt, down)
}

/// Sets the prescaler and the period (register values; preloaded, taking effect at the next
/// update) and the sense trigger's lead for them (below the period), `arr` at most `max_arr`.
pub fn set_timing(tim: pac::timer::TimAdv, psc: u32, arr: u32, max_arr: u32, lead: u32) {
    let arr = arr.min(max_arr).max(2);
    tim.psc().write_value(psc.min(u16::MAX as u32) as u16);
    tim.arr().write(|w| w.set_arr(arr as u16));
    tim.ccr(3).write(|w| w.set_ccr(lead.min(arr - 1) as u16));
}

/// What the update alignment needs of a centre-aligned timer.
pub trait UpdateTimer {
    /// Clears the update flag (UIF) alone.
    fn clear_update(&mut self);
    /// The update flag.
    fn update_pending(&mut self) -> bool;
    /// The counter counts up (CR1.DIR, read-only in centre-aligned mode).
    fn counting_up(&mut self) -> bool;
    /// Writes the repetition counter's reload (RCR).
    fn set_repetition(&mut self, rep: u8);
}

impl UpdateTimer for pac::timer::TimAdv {
    fn clear_update(&mut self) {
        self.sr().write(|w| w.0 = SR_CLEAR_UIF);
    }
    fn update_pending(&mut self) -> bool {
        self.sr().read().uif()
    }
    fn counting_up(&mut self) -> bool {
        self.cr1().read().dir() == pac::timer::vals::Dir::UP
    }
    fn set_repetition(&mut self, rep: u8) {
        self.rcr().write(|w| w.set_rep(rep as u16));
    }
}

/// Polls for the next update event allowed (hundreds of periods at the CPU's speed).
pub const UPDATE_POLLS: u32 = 1_000_000;

/// Waits (at most `polls` reads of UIF) for the timer's next update event; the counter's
/// direction just after it: `Some(true)` counting up (the update was at the bottom),
/// `Some(false)` down (at the top), `None` if none came.
pub fn next_update_counting_up(t: &mut impl UpdateTimer, polls: u32) -> Option<bool> {
    t.clear_update();
    for _ in 0..polls {
        if t.update_pending() {
            return Some(t.counting_up());
        }
    }
    None
}

/// Puts the timer's update event at the counter's bottom, once per period, and checks it; true
/// if it is there. The repetition counter reloads from RCR at each update, and an update comes
/// at a turning point that finds it at 0 (RM0090 §17.3.3, figure "Update rate examples"):
/// with RCR = 0 every turning point updates; RCR = 1 written just after an update at the top
/// is loaded at the next update, the bottom, and from then on every other turning point —
/// every bottom — updates (RM0090's "RCR written after the counter started: the update on
/// the underflow"). Checked on two updates. Run before the control interrupt, with the bridge
/// off.
pub fn align_update_to_bottom(t: &mut impl UpdateTimer, polls: u32) -> bool {
    t.set_repetition(0);
    // Two updates: the repetition counter now reloads from 0 at every turning point.
    let _ = next_update_counting_up(t, polls);
    let _ = next_update_counting_up(t, polls);
    // RCR = 1 right after an update at the top (the counter then counts down).
    let mut written = false;
    for _ in 0..4 {
        if next_update_counting_up(t, polls) == Some(false) {
            t.set_repetition(1);
            written = true;
            break;
        }
    }
    if !written {
        return false;
    }
    // One update to load it, then two that must both be at the bottom.
    let _ = next_update_counting_up(t, polls);
    next_update_counting_up(t, polls) == Some(true)
        && next_update_counting_up(t, polls) == Some(true)
}

/// Arms the deadman's tick: UIF cleared, the update interrupt enabled (DIER.UIE).
pub fn deadman_arm(tim: pac::timer::TimAdv) {
    tim.sr().write(|w| w.0 = SR_CLEAR_UIF);
    tim.dier().modify(|w| w.set_uie(true));
}

/// The deadman's tick at an update event: UIF cleared, `deadman` ticked with the step count;
/// on a trip (true: the caller switches the bridge off) the update interrupt is switched off.
#[inline(always)]
pub fn deadman_tick(tim: pac::timer::TimAdv, deadman: &mut Deadman, steps: u32) -> bool {
    tim.sr().write(|w| w.0 = SR_CLEAR_UIF);
    let trip = deadman.tick(steps);
    if trip {
        tim.dier().modify(|w| w.set_uie(false));
    }
    trip
}

/// The bridge's two inputs as registers, for gms-core's `drive::bridge_off` (its order:
/// the timer's outputs off, the pins' latches low, then the pins to the GPIO).
#[derive(Clone, Copy)]
pub struct BridgeRegs {
    /// The PWM timer.
    pub tim: pac::timer::TimAdv,
    /// The inputs' port.
    pub gpio: pac::gpio::Gpio,
    /// The inputs' pins on it.
    pub pins: [usize; 2],
}

impl BridgeOff for BridgeRegs {
    fn disable_timer_outputs(&mut self) {
        // MOE cleared: with OSSI set and OIS1/OIS2 at 0 both outputs go to their idle level,
        // low (RM0090 §17.4.18 TIMx_BDTR, table 95 "Output control bits").
        self.tim.bdtr().modify(|w| w.set_moe(false));
    }
    fn latch_pins_low(&mut self) {
        let pins = self.pins;
        self.gpio.bsrr().write(|w| {
            for pin in pins {
                w.set_br(pin, true);
            }
        });
    }
    fn pins_to_gpio_outputs(&mut self) {
        let pins = self.pins;
        self.gpio.moder().modify(|w| {
            for pin in pins {
                w.set_moder(pin, pac::gpio::vals::Moder::OUTPUT);
            }
        });
    }
}
