//! Time outside the core: the peripherals' events (TIM8's update and trigger, TIM4, the ADC's
//! conversions and their DMA, the USART and its DMA) fired at their own cycles, their lines
//! raised as pending interrupts, the plant advanced to each PWM update at the duty then in
//! force, and the image's RTT log read as a probe would. The sources are the models' own
//! (`crate::periph`: RM0090 §17 the advanced timer, §13 the ADC, §10 the DMA, §30 the USART).

use super::*;

impl Machine {
    /// The peripherals' asserted lines made pending (level-sensitive: pending again after
    /// the handler returns while the line is still high), unless the exception is active.
    pub(super) fn raise_lines(&mut self) {
        let lines = self.chip().p.irq_lines();
        let c = self.chip_mut();
        for l in lines {
            let n = exc::IRQ0 + l as u32;
            if !c.active.iter().any(|a| a.exc == n) {
                c.core.set_irq_pending(l);
            }
        }
    }

    /// The next peripheral event \[cycles\].
    pub(super) fn next_event(&self) -> u64 {
        let p = &self.chip().p;
        [
            p.tim8.next_event(),
            p.tim4.next_event(),
            p.adc.next_event(),
            p.usart2.next_event(),
            p.usb_host.next_event(),
            p.iwdg.expires,
        ]
        .into_iter()
        .flatten()
        .min()
        .unwrap_or(u64::MAX)
    }

    /// Fires every peripheral event due by now, in time order.
    pub(super) fn fire_events(&mut self) {
        loop {
            let now = self.chip().cycles;
            let p = &self.chip().p;
            let cands = [
                (0, p.tim8.next_event()),
                (1, p.tim4.next_event()),
                (2, p.adc.next_event()),
                (3, p.usart2.next_event()),
                (4, p.usb_host.next_event()),
            ];
            let Some((which, t)) = cands
                .into_iter()
                .filter_map(|(w, t)| t.map(|t| (w, t)))
                .filter(|&(_, t)| t <= now)
                .min_by_key(|&(_, t)| t)
            else {
                break;
            };
            match which {
                0 => self.fire_tim8(t),
                1 => {
                    let c = self.chip_mut();
                    c.p.tim4.fire(t);
                    c.p.tim4.take_events();
                }
                2 => self.fire_adc(t),
                3 => self.fire_usart(t),
                _ => {
                    let p = &mut self.chip_mut().p;
                    // The boards' 8 MHz crystal (board.rs of both).
                    p.otg.clk48_hz = p.rcc.pll48_hz(8_000_000);
                    p.usb_host.fire(t, &mut p.otg);
                }
            }
        }
        // A DMA transmit waiting for the line.
        self.kick_tx();
    }

    pub(super) fn fire_tim8(&mut self, t: u64) {
        let c = self.chip_mut();
        c.p.tim8.fire(t);
        // Each event at its own time: one fired by a register write's catch-up (inside a
        // run, after the event was due) waited here since, and an ADC trigger handled at
        // this call's `t` instead would start the sequence late (seen: a trigger queued by
        // the control step's compare write, taken at the next bottom, 1,750 cycles late,
        // and the sense's DMA interrupt a period late after it: `overrun`).
        let events = c.p.tim8.take_events();
        for (at, e) in events {
            match e {
                tim::Event::Update { bottom: true } => self.plant_period(at),
                tim::Event::Trigger => {
                    let c = self.chip_mut();
                    if c.p.adc.on_tim8_trgo() {
                        c.p.adc.trigger(at);
                    }
                }
                _ => {}
            }
        }
    }

    /// The update event at the bottom, `t`: the plant brought to it at the duty of the period
    /// that ended, then the compare values the update made active applied from here on (the
    /// duty the control step wrote during the period drives the next one: RM0090 §17.3.7,
    /// preload, OCxPE).
    pub(super) fn plant_period(&mut self, t: u64) {
        self.advance_plant(t);
        self.applied_duty = self.bridge_duty();
        let period = self.chip().p.tim8.period_cycles() as f64 / HZ as f64;
        self.plant.start_period(self.applied_duty, period);
    }

    /// The plant advanced from where it was to `t` \[cycles\] at the applied duty, in steps of
    /// 5 µs at most; the encoder's count from it. The outputs off (MOE cleared, the pins
    /// taken from the timer) take the voltage off from the last event on. A gap over 10 ms
    /// (the PWM not yet running) moves the plant's clock without stepping it.
    pub(super) fn advance_plant(&mut self, t: u64) {
        let Some(cycles) = t.checked_sub(self.plant_at).filter(|&c| c > 0) else {
            return;
        };
        self.plant_at = t;
        let dt = cycles as f64 / HZ as f64;
        let on = self.bridge_on();
        self.plant.set_outputs(on);
        if dt < 0.01 {
            let n = (dt / 5e-6).ceil().max(1.0) as usize;
            for _ in 0..n {
                self.plant.step(dt / n as f64);
            }
        }
        let counts = self.plant.encoder();
        let c = self.chip_mut();
        if !c.inject.encoder_frozen {
            c.enc_counts = counts;
        }
    }

    /// The bridge's mean duty over a period \[−1, 1\]: IN1's high fraction minus IN2's
    /// (PWM mode 1, centre-aligned: high while CNT < CCR), 0 when the outputs are off (MOE
    /// clear, or the pins taken from the timer as GPIO outputs).
    pub fn bridge_duty(&self) -> f64 {
        if !self.bridge_on() {
            return 0.0;
        }
        let p = &self.chip().p;
        let arr = p.tim8.arr().max(1) as f64;
        let f = |c: u32| (c as f64).min(arr) / arr;
        f(p.tim8.ccr(0)) - f(p.tim8.ccr(1))
    }

    /// Whether the bridge's inputs switch: the outputs on ([`Machine::bridge_on`]) and not
    /// both held low by their compare values (CCR 0 in PWM mode 1: the coast a fault or
    /// `disable` leaves, the driver's outputs off).
    pub fn bridge_driving(&self) -> bool {
        let p = &self.chip().p;
        self.bridge_on() && (p.tim8.ccr(0) != 0 || p.tim8.ccr(1) != 0)
    }

    /// Whether the bridge drives (MOE set and both pins on the timer).
    pub fn bridge_on(&self) -> bool {
        let p = &self.chip().p;
        let moe = p.tim8.reg(0x44 / 4) & (1 << 15) != 0;
        let moder = p.plain.get(&base::GPIOC).copied().unwrap_or(0);
        moe && (moder >> 12) & 3 == 2 && (moder >> 14) & 3 == 2
    }

    pub(super) fn fire_adc(&mut self, t: u64) {
        self.advance_plant(t);
        if self.chip().p.adc.injected_due(t) {
            // The supply divider's injected conversion (the boards' PC1: the plant's supply
            // terminal through the divider gms-core's power stage describes for both boards).
            let b = gms_core::boards::f405::BOARD;
            let v = self.plant.supply_volts();
            let code = b
                .supply
                .map_or(0, |ss| ss.code(v, b.sense.vref, b.sense.full_scale));
            self.chip_mut().p.adc.take_injected(code);
            return;
        }
        // The current at the sampling instant through the board's sense chain: 3.4 V/A
        // around 1.65 V, 4095 codes over 3.3 V (power_stage.rs). One conversion of the
        // sequence the firmware averages: the scenario's noise is the average's, so one
        // conversion has sqrt(length) times it; quantised once, here.
        let n = self.chip().p.adc.length() as f64;
        let amps = self.plant.sense(n.sqrt());
        let zero = 2048.0 + self.plant.sense_offset_codes();
        let (lo, hi) = self.sense_limits;
        let code = (zero + amps * 3.4 * 4095.0 / 3.3)
            .round()
            .clamp(lo.ceil(), hi.floor()) as u32;
        let code = self.chip().inject.sense_code.unwrap_or(code);
        let code = self
            .chip_mut()
            .inject
            .sense_code_once
            .take()
            .unwrap_or(code);
        let c = self.chip_mut();
        if c.p.adc.take_conversion(t, code) {
            // DMA2 stream 0, channel 0 (ADC1): a halfword into memory.
            if let Some(addr) = c.p.dma2.next_address(0) {
                let v = c.p.adc.dma_read();
                let size = c.p.dma2.streams[0].msize() as usize;
                let bytes = v.to_le_bytes();
                if self.uc.mem_write(addr as u64, &bytes[..size]).is_ok() {
                    self.chip_mut().p.dma2.transferred(0);
                } else {
                    self.chip_mut().p.dma2.error(0);
                }
            }
        }
    }

    pub(super) fn fire_usart(&mut self, t: u64) {
        let c = self.chip_mut();
        match c.p.usart2.fire(t) {
            usart::LineEvent::Received(b) => {
                if c.p.usart2.dma_rx() {
                    if let Some(addr) = c.p.dma1.next_address(5) {
                        if self.uc.mem_write(addr as u64, &[b]).is_ok() {
                            self.chip_mut().p.dma1.transferred(5);
                        } else {
                            self.chip_mut().p.dma1.error(5);
                        }
                    } else {
                        // Nobody took it: an overrun.
                        self.chip_mut().p.usart2.write(0, !0, t);
                    }
                }
                let c = self.chip_mut();
                c.p.usart2.poll_host(t);
            }
            usart::LineEvent::TxFree => self.kick_tx(),
            usart::LineEvent::None => {}
        }
    }

    /// The DMA gives the transmitter its next byte when the line is free.
    pub(super) fn kick_tx(&mut self) {
        let c = self.chip();
        if !c.p.usart2.dma_tx() || !c.p.usart2.tx_free() {
            return;
        }
        let Some(addr) = c.p.dma1.next_address(6) else {
            return;
        };
        let mut b = [0u8; 1];
        if self.uc.mem_read(addr as u64, &mut b).is_err() {
            self.chip_mut().p.dma1.error(6);
            return;
        }
        let c = self.chip_mut();
        let now = c.cycles;
        c.p.usart2.send(b[0], now);
        c.p.dma1.transferred(6);
    }

    /// Reads the RTT channel as a probe would and decodes the new lines.
    pub(super) fn read_log(&mut self) {
        let (Some(cb), Some(_)) = (self.rtt_cb, self.log.as_ref()) else {
            return;
        };
        let ch = rtt::Channel::up0(cb);
        let (Ok(buf), Ok(size), Ok(wr), Ok(rd)) = (
            self.read_u32(ch.buffer),
            self.read_u32(ch.size),
            self.read_u32(ch.write),
            self.read_u32(ch.read),
        ) else {
            return;
        };
        if size == 0 || wr == rd || wr >= size || rd >= size {
            return;
        }
        let mut bytes = Vec::new();
        let mut r = rd;
        while r != wr {
            let end = if wr > r { wr } else { size };
            let mut chunk = vec![0u8; (end - r) as usize];
            if self.uc.mem_read((buf + r) as u64, &mut chunk).is_err() {
                return;
            }
            bytes.extend_from_slice(&chunk);
            r = if end == size { 0 } else { end };
        }
        let _ = self.write_u32(ch.read, wr);
        let t = self.seconds();
        if let Some(log) = self.log.as_mut() {
            for line in log.feed(&bytes) {
                if self.echo_log {
                    eprintln!("{t:10.6} {line}");
                }
                self.log_lines.push(line);
            }
        }
    }
}
