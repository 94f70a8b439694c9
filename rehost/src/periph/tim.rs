//! The STM32F4's general-purpose and advanced timers (RM0090 §17-18, RM0390 §16-17; offsets
//! from the timer's base): the counter in edge-aligned up-counting and centre-aligned mode,
//! the prescaler and auto-reload with their preloads, the repetition counter (advanced
//! timers: an update event every RCR + 1 turning points), UG, the status flags (written 0 to
//! clear), the compare flags, OC4REF as a trigger output in PWM mode, and the update and
//! compare interrupts. Time is counted in the core's cycles; the timer's tick is
//! `clock_div · (PSC + 1)` of them.

/// CR1.CEN.
const CEN: u32 = 1;
/// CR1.URS.
const URS: u32 = 1 << 2;
/// CR1.DIR.
const DIR: u32 = 1 << 4;
/// CR1.ARPE.
const ARPE: u32 = 1 << 7;

/// What a timer event did, for the machine to act on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Event {
    /// An update event (the preloaded compare values now active).
    Update {
        /// True at the counter's bottom (underflow or overflow to 0), false at the top.
        bottom: bool,
    },
    /// OC4REF rose with CR2.MMS = 111 (OC4REF as TRGO): the trigger output.
    Trigger,
    /// Any other flag set (a compare match).
    Compare,
}

/// One timer.
#[derive(Debug, Clone)]
pub struct Timer {
    regs: [u32; 0x54 / 4],
    /// Active (not preload) prescaler and auto-reload.
    psc: u32,
    arr: u32,
    /// Active compare values (with OCxPE, taken from the preload at an update event).
    ccr: [u32; 4],
    /// The counter at `t_ref` and its direction there (centre-aligned: true counting down).
    cnt: u32,
    down: bool,
    t_ref: u64,
    rep: u32,
    /// The timer's clock as a divisor of the core's: 1 on APB2 at 168 MHz, 2 on APB1.
    clock_div: u64,
    /// The counter's width mask (0xFFFF or 0xFFFF_FFFF).
    mask: u32,
    /// Whether it has a repetition counter (TIM1/TIM8).
    advanced: bool,
    /// Events not yet taken by the machine, with their times \[cycles\] (those fired by a
    /// register access's catch-up come before the access's own time).
    events: Vec<(u64, Event)>,
}

const CR1: usize = 0;
const CR2: usize = 1;
const DIER: usize = 3;
const SR: usize = 4;
const CCMR1: usize = 6;
const CCMR2: usize = 7;
const PSC: usize = 10;
const ARR: usize = 11;
const RCR: usize = 12;
const CCR1: usize = 13;

impl Timer {
    /// A timer at reset: `clock_div` as above, `bits` 16 or 32, `advanced` for TIM1/TIM8.
    pub fn new(clock_div: u64, bits: u32, advanced: bool) -> Timer {
        let mask = if bits >= 32 {
            u32::MAX
        } else {
            (1 << bits) - 1
        };
        let mut regs = [0; 0x54 / 4];
        regs[ARR] = mask;
        Timer {
            regs,
            psc: 0,
            arr: mask,
            ccr: [0; 4],
            cnt: 0,
            down: false,
            t_ref: 0,
            rep: 0,
            clock_div,
            mask,
            advanced,
            events: Vec::new(),
        }
    }

    fn tick(&self) -> u64 {
        self.clock_div * (self.psc as u64 + 1)
    }

    fn running(&self) -> bool {
        self.regs[CR1] & CEN != 0
    }

    /// Centre-aligned (CMS ≠ 0).
    pub fn centre(&self) -> bool {
        (self.regs[CR1] >> 5) & 3 != 0
    }

    /// The active auto-reload value.
    pub fn arr(&self) -> u32 {
        self.arr
    }

    /// The counter's period in core cycles: 2 × ARR ticks centre-aligned (up to ARR, down to
    /// 0: RM0090 §17.3.2), ARR + 1 edge-aligned.
    pub fn period_cycles(&self) -> u64 {
        let counts = if self.centre() {
            2 * self.arr as u64
        } else {
            self.arr as u64 + 1
        };
        counts * self.tick()
    }

    /// The active compare value of channel `ch` (0-3).
    pub fn ccr(&self, ch: usize) -> u32 {
        self.ccr[ch]
    }

    /// The raw register at index `i` (offset / 4).
    pub fn reg(&self, i: usize) -> u32 {
        self.regs.get(i).copied().unwrap_or(0)
    }

    /// The clock security system's failure event at the break input (advanced timers; RM0090
    /// §7.2.7, §17.3.12): with BDTR.BKE set, MOE cleared at once (the outputs to their
    /// off-state) and SR.BIF set; without BKE, nothing. The break pin is not modelled (no
    /// image gives it to the timer).
    pub fn clock_failure(&mut self) {
        const BDTR: usize = 0x44 / 4;
        const BKE: u32 = 1 << 12;
        const MOE: u32 = 1 << 15;
        const BIF: u32 = 1 << 7;
        if self.advanced && self.regs[BDTR] & BKE != 0 {
            self.regs[BDTR] &= !MOE;
            self.regs[SR] |= BIF;
        }
    }

    /// The interrupt line: a status flag set whose interrupt is enabled.
    pub fn irq(&self) -> bool {
        self.regs[SR] & self.regs[DIER] & 0xFF != 0
    }

    /// Whether the update interrupt alone is asserted (TIM8_UP's line).
    pub fn irq_update(&self) -> bool {
        self.regs[SR] & self.regs[DIER] & 1 != 0
    }

    /// Whether events wait to be taken.
    pub fn has_events(&self) -> bool {
        !self.events.is_empty()
    }

    /// The events since the last call, each with its time \[cycles\].
    pub fn take_events(&mut self) -> Vec<(u64, Event)> {
        core::mem::take(&mut self.events)
    }

    /// Brings the counter to `now` (whole ticks). The events due before `now` are fired on
    /// the way (their flags set, their [`Event`]s queued): the machine fires events between
    /// its runs, but a register access inside a run can come after an event's time (the run
    /// stops at block boundaries), and moving the counter past a compare value without its
    /// match would put the match a whole wrap later.
    fn sync(&mut self, now: u64) {
        if !self.running() || now <= self.t_ref {
            return;
        }
        while let Some(t) = self.next_event().filter(|&t| t <= now) {
            self.fire(t);
        }
        let ticks = (now - self.t_ref) / self.tick();
        if ticks == 0 {
            return;
        }
        self.t_ref += ticks * self.tick();
        self.move_by(ticks);
    }

    /// Moves the counter by `ticks` within the current segment (no turning point crossed
    /// except landing on one).
    fn move_by(&mut self, ticks: u64) {
        let t = ticks as u32;
        if self.down {
            self.cnt = self.cnt.saturating_sub(t);
        } else {
            self.cnt = self.cnt.wrapping_add(t) & self.mask;
        }
    }

    /// Ticks from the counter's position to the next turning point (centre) or overflow
    /// (edge-aligned up).
    fn ticks_to_boundary(&self) -> u64 {
        if self.centre() {
            if self.down {
                self.cnt.max(1) as u64
            } else {
                (self.arr.saturating_sub(self.cnt)).max(1) as u64
            }
        } else {
            (self.arr as u64 + 1).saturating_sub(self.cnt as u64).max(1)
        }
    }

    /// OC4REF's rising edge as a trigger: CR2.MMS = 111, channel 4 in PWM mode 1 (OC4M =
    /// 110: active while CNT < CCR4), so it rises counting down as CNT passes below CCR4.
    fn trigger_ticks(&self) -> Option<u64> {
        let mms = (self.regs[CR2] >> 4) & 7;
        let oc4m = (self.regs[CCMR2] >> 12) & 7;
        if mms != 7 || oc4m != 6 || !self.centre() || !self.down {
            return None;
        }
        let c = self.ccr[3];
        (c >= 1 && self.cnt >= c).then(|| (self.cnt - c + 1) as u64)
    }

    /// Ticks from the counter to channel `ch`'s next compare match (edge-aligned counting
    /// up), if its compare value is within the period: CCxIF is set on the count that reaches
    /// CCRx whether or not its interrupt is enabled (RM0090 §18.3.7).
    fn compare_ticks_of(&self, ch: usize) -> Option<u64> {
        let c = self.ccr[ch];
        if self.centre() || c > self.arr {
            return None;
        }
        Some(if c > self.cnt {
            (c - self.cnt) as u64
        } else {
            (self.arr as u64 + 1 - self.cnt as u64) + c as u64
        })
    }

    /// Ticks to the next compare match of any channel.
    fn compare_ticks(&self) -> Option<u64> {
        (0..4).filter_map(|ch| self.compare_ticks_of(ch)).min()
    }

    /// When the next event is due \[cycles\], if the counter runs.
    pub fn next_event(&self) -> Option<u64> {
        if !self.running() {
            return None;
        }
        let mut ticks = self.ticks_to_boundary();
        if let Some(t) = self.trigger_ticks() {
            ticks = ticks.min(t);
        }
        if let Some(t) = self.compare_ticks() {
            ticks = ticks.min(t);
        }
        Some(self.t_ref + ticks * self.tick())
    }

    /// Fires the event due at `t` (= [`Timer::next_event`]).
    pub fn fire(&mut self, t: u64) {
        if !self.running() || t < self.t_ref {
            return;
        }
        let ticks = (t - self.t_ref) / self.tick();
        let boundary = self.ticks_to_boundary();
        let trigger = self.trigger_ticks();
        // Every channel that matches on this count (embassy's time driver can put its alarm
        // on the same count as its half-period compare, CCR1 = CCR2 = 0x8000).
        let matched: Vec<usize> = (0..4)
            .filter(|&ch| self.compare_ticks_of(ch) == Some(ticks))
            .collect();
        self.t_ref += ticks * self.tick();
        if ticks >= boundary {
            self.move_by(boundary);
            self.turning_point(t);
        } else {
            self.move_by(ticks);
        }
        if trigger == Some(ticks) {
            self.events.push((t, Event::Trigger));
            self.regs[SR] |= 1 << 4; // CC4IF
        }
        for &ch in &matched {
            self.regs[SR] |= 2 << ch;
        }
        if !matched.is_empty() {
            self.events.push((t, Event::Compare));
        }
    }

    /// An overflow (edge-aligned: the counter wraps to 0; centre: top, counting down from
    /// now) or underflow (centre: bottom), at `t` \[cycles\].
    fn turning_point(&mut self, t: u64) {
        let bottom;
        if self.centre() {
            if self.down {
                // At 0: counting up again.
                self.cnt = 0;
                self.down = false;
                bottom = true;
            } else {
                self.cnt = self.arr;
                self.down = true;
                bottom = false;
            }
        } else {
            self.cnt = 0;
            bottom = true;
        }
        if self.advanced && self.rep > 0 {
            self.rep -= 1;
            return;
        }
        self.rep = self.regs[RCR] & 0xFF;
        self.update(false);
        self.events.push((t, Event::Update { bottom }));
    }

    /// An update event: the preloads become active; UIF unless it came from UG with URS.
    fn update(&mut self, from_ug: bool) {
        self.psc = self.regs[PSC] & 0xFFFF;
        self.arr = self.regs[ARR] & self.mask;
        for ch in 0..4 {
            self.ccr[ch] = self.regs[CCR1 + ch] & self.mask;
        }
        if !(from_ug && self.regs[CR1] & URS != 0) {
            self.regs[SR] |= 1;
        }
    }

    /// Whether channel `ch`'s compare value is preloaded (OCxPE).
    fn preloaded(&self, ch: usize) -> bool {
        let ccmr = if ch < 2 {
            self.regs[CCMR1]
        } else {
            self.regs[CCMR2]
        };
        ccmr & (1 << (3 + 8 * (ch % 2))) != 0
    }

    /// Reads the register at `off` at `now` \[cycles\].
    pub fn read(&mut self, off: u32, now: u64) -> u32 {
        self.sync(now);
        let i = off as usize / 4;
        match i {
            CR1 => {
                let dir = if self.centre() && self.down { DIR } else { 0 };
                (self.regs[CR1] & !DIR)
                    | dir
                    | if self.centre() {
                        0
                    } else {
                        self.regs[CR1] & DIR
                    }
            }
            9 => self.cnt, // CNT
            _ => self.reg(i),
        }
    }

    /// Writes the register at `off` at `now` \[cycles\].
    pub fn write(&mut self, off: u32, value: u32, now: u64) {
        self.sync(now);
        let i = off as usize / 4;
        match i {
            CR1 => {
                let was = self.running();
                self.regs[CR1] = value;
                if !was && self.running() {
                    self.t_ref = now;
                }
            }
            SR => self.regs[SR] &= value, // rc_w0
            5 => {
                // EGR.UG: the counter restarts, the repetition counter reloads, the preloads
                // take effect.
                if value & 1 != 0 {
                    self.cnt = 0;
                    self.down = false;
                    self.rep = self.regs[RCR] & 0xFF;
                    self.t_ref = now;
                    self.update(true);
                }
                self.regs[SR] |= value & 0x1E; // CCxG
            }
            9 => {
                self.cnt = value & self.mask;
                self.t_ref = now;
            }
            PSC => self.regs[PSC] = value & 0xFFFF,
            ARR => {
                self.regs[ARR] = value & self.mask;
                if self.regs[CR1] & ARPE == 0 {
                    self.arr = value & self.mask;
                }
            }
            13..=16 => {
                let ch = i - CCR1;
                self.regs[i] = value & self.mask;
                if !self.preloaded(ch) {
                    self.ccr[ch] = value & self.mask;
                }
            }
            _ => {
                if let Some(r) = self.regs.get_mut(i) {
                    *r = value;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs the timer's events up to `until`, returning them with their times.
    fn run(t: &mut Timer, until: u64) -> Vec<(u64, Event)> {
        let mut out = Vec::new();
        while let Some(at) = t.next_event() {
            if at > until {
                break;
            }
            t.fire(at);
            out.extend(t.take_events());
        }
        out
    }

    #[test]
    fn a_clock_failure_breaks_only_with_bke() {
        let mut t = Timer::new(1, 16, true);
        t.write(0x44, 1 << 15, 0);
        t.clock_failure();
        assert_eq!(t.reg(0x44 / 4) & (1 << 15), 1 << 15, "no BKE: MOE kept");
        t.write(0x44, (1 << 15) | (1 << 13) | (1 << 12), 0);
        t.clock_failure();
        assert_eq!(t.reg(0x44 / 4) & (1 << 15), 0, "BKE: MOE cleared");
        assert_eq!(t.reg(SR) & (1 << 7), 1 << 7, "BIF");
        let mut g = Timer::new(2, 16, false);
        g.write(0x44, 1 << 12, 0);
        g.clock_failure();
        assert_eq!(g.reg(SR), 0, "a general-purpose timer has no break");
    }

    #[test]
    fn an_up_counter_overflows_every_arr_plus_one_ticks_and_matches_its_compare() {
        // TIM4 on APB1 (tick = 2 cycles · (PSC + 1)): PSC 83 → 1 MHz at 168 MHz; ARR 0xFFFF.
        let mut t = Timer::new(2, 16, false);
        t.write(0x28, 83, 0);
        t.write(0x2C, 0xFFFF, 0);
        t.write(0x14, 1, 0); // UG: PSC active
        t.write(0x10, 0, 0);
        t.write(0x34, 0x8000, 0); // CCR1
        t.write(0x0C, 1 | 2, 0); // UIE, CC1IE
        t.write(0x00, 1, 0);
        let ev = run(&mut t, 168 * 70_000);
        assert_eq!(ev[0], (168 * 0x8000, Event::Compare));
        assert_eq!(ev[1], (168 * 0x10000, Event::Update { bottom: true }));
        assert!(t.irq());
        assert_eq!(t.read(0x24, 168 * 0x10010), 0x10);
        t.write(0x10, !1, 168 * 0x10010);
        assert_eq!(t.reg(4) & 1, 0, "UIF cleared by writing 0");
    }

    #[test]
    fn a_centre_aligned_timer_with_rcr_1_updates_at_every_other_turning_point() {
        // TIM8: 20 kHz centre-aligned at 168 MHz: ARR 4200, PSC 0; RCR 1.
        let mut t = Timer::new(1, 16, true);
        t.write(0x00, 3 << 5, 0); // CMS = 11
        t.write(0x2C, 4200, 0);
        t.write(0x30, 1, 0);
        t.write(0x14, 1, 0); // UG: rep = 1, counter 0
        t.write(0x10, 0, 0);
        t.write(0x00, (3 << 5) | 1, 0);
        let ev = run(&mut t, 3 * 8400);
        let updates: Vec<_> = ev
            .iter()
            .filter(|(_, e)| matches!(e, Event::Update { .. }))
            .collect();
        // Turning points at 4200 (top), 8400 (bottom), 12600 (top), …: with RCR = 1 from a UG
        // at the bottom, the update comes at the second, the bottom: every 8400 cycles.
        assert_eq!(updates[0], &(8400, Event::Update { bottom: true }));
        assert_eq!(updates[1], &(16800, Event::Update { bottom: true }));
        // Counting down just after a top.
        run(&mut t, 3 * 8400 + 4200);
        assert_ne!(t.read(0x00, 3 * 8400 + 4300) & DIR, 0);
        run(&mut t, 4 * 8400);
        assert_eq!(t.read(0x00, 4 * 8400 + 100) & DIR, 0);
    }

    /// TIM8 centre-aligned over ARR 4200 with OC4REF (PWM mode 1, CCR4 = 100) as its trigger
    /// output, started from a UG at 0 (the firmware's sense trigger).
    fn oc4ref_trigger_at_100() -> Timer {
        let mut t = Timer::new(1, 16, true);
        t.write(0x00, 3 << 5, 0);
        t.write(0x2C, 4200, 0);
        t.write(0x04, 7 << 4, 0); // MMS = OC4REF
        t.write(0x1C, 6 << 12, 0); // OC4M = PWM mode 1, no preload
        t.write(0x40, 100, 0); // CCR4
        t.write(0x14, 1, 0);
        t.write(0x00, (3 << 5) | 1, 0);
        t
    }

    #[test]
    fn oc4ref_triggers_counting_down_as_it_passes_below_ccr4() {
        let mut t = oc4ref_trigger_at_100();
        let ev = run(&mut t, 8400);
        let trig: Vec<_> = ev.iter().filter(|(_, e)| *e == Event::Trigger).collect();
        // Down from 4200 at 4200 cycles; CNT = 99 after 4101 ticks: 100 ticks before the bottom.
        assert_eq!(trig, vec![&(8400 - 99, Event::Trigger)]);
    }

    #[test]
    fn a_trigger_fired_by_a_writes_catch_up_keeps_its_own_time() {
        // As the control step writes the bridge's compare values after the ADC's trigger was
        // due (the run stops at block boundaries): the trigger is taken with its time, not
        // the write's or the next event's.
        let mut t = oc4ref_trigger_at_100();
        run(&mut t, 8000);
        assert!(t.take_events().is_empty());
        t.write(0x34, 2000, 8400 - 50);
        assert!(t.has_events());
        assert_eq!(t.take_events(), vec![(8400 - 99, Event::Trigger)]);
    }

    /// TIM4 as embassy's time driver runs it: 1 MHz (168 cycles a tick), free-running.
    fn tim4_as_embassy() -> Timer {
        let mut t = Timer::new(2, 16, false);
        t.write(0x28, 83, 0); // PSC
        t.write(0x2C, 0xFFFF, 0); // ARR
        t.write(0x14, 1, 0); // EGR.UG
        t.write(0x00, 1, 0); // CR1.CEN
        t
    }

    /// A register access after a compare's time (within one run of the core) sets its flag
    /// then, not a whole wrap later.
    #[test]
    fn a_compare_passed_before_an_access_still_matches() {
        let mut t = tim4_as_embassy();
        t.write(0x38, 10, 0); // CCR2: a match at tick 10
        // The next access at tick 12: CC2IF is set, the counter at 12.
        assert_eq!(t.read(0x24, 12 * 168), 12);
        assert_ne!(t.read(0x10, 12 * 168) & (1 << 2), 0, "CC2IF");
    }

    /// Two channels with the same compare value both match on that count (the image's
    /// supervisor stopped, the watchdog reset it, when embassy's alarm fell on its
    /// half-period compare and only one flag was set).
    #[test]
    fn two_channels_on_the_same_count_both_match() {
        let mut t = tim4_as_embassy();
        t.write(0x34, 0x8000, 0); // CCR1
        t.write(0x38, 0x8000, 0); // CCR2
        run(&mut t, 0x8001 * 168);
        assert_eq!(t.read(0x10, 0x8001 * 168) & 0b110, 0b110, "CC1IF and CC2IF");
    }

    #[test]
    fn preloaded_compare_values_take_effect_at_the_update() {
        let mut t = Timer::new(1, 16, true);
        t.write(0x18, 1 << 3, 0); // OC1PE
        t.write(0x00, 3 << 5, 0);
        t.write(0x2C, 1000, 0);
        t.write(0x14, 1, 0);
        t.write(0x00, (3 << 5) | 1, 0);
        t.write(0x34, 500, 10);
        assert_eq!(t.ccr(0), 0, "still the old value");
        run(&mut t, 2000);
        assert_eq!(t.ccr(0), 500);
    }
}
