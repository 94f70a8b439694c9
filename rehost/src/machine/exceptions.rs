//! The core's exception model (ARMv7-M ARM B1.5): the execution priority and what is
//! pending above it (B1.5.4), exception entry with the basic or the extended frame and lazy FP
//! stacking (B1.5.6-7), exception return (B1.5.8), synchronous faults and their escalation to
//! HardFault (B1.5.5). Unicorn's own M-profile NVIC is stubbed out: these are taken here,
//! between runs of the engine.

use unicorn_engine::RegisterARM as R;

use super::bus::reg_s;
use super::*;

impl Chip {
    /// The most urgent group priority of the active exceptions (256, below any, in thread
    /// mode).
    pub(super) fn active_priority(&self) -> i32 {
        self.active
            .iter()
            .map(|a| self.core.group_priority(a.exc))
            .min()
            .unwrap_or(256)
    }
}

impl Machine {
    /// The execution priority (B1.5.4): the most urgent of the active exceptions', BASEPRI
    /// and, with `primask`, PRIMASK (0).
    pub(super) fn execution_priority(&self, primask: bool) -> i32 {
        let mut p = self.active_priority();
        let basepri = self.reg(R::BASEPRI) & 0xFF;
        if basepri != 0 {
            p = p.min(basepri as i32);
        }
        if primask && self.reg(R::PRIMASK) & 1 != 0 {
            p = p.min(0);
        }
        p
    }

    /// The most urgent pending, enabled exception above the execution priority (ties to the
    /// lower number); `primask` false asks what would wake a WFE/WFI, which PRIMASK does not
    /// hold off.
    pub(super) fn pending_above(&self, primask: bool) -> Option<u32> {
        self.pending_over(self.execution_priority(primask))
    }

    /// Whether an interrupt is pending that only PRIMASK or BASEPRI keeps from being taken
    /// (it would preempt the active exceptions).
    pub(super) fn pending_masked(&self) -> bool {
        self.pending_over(self.active_priority()).is_some()
    }

    /// The most urgent group priority of the active exceptions ([`Chip::active_priority`]).
    pub(super) fn active_priority(&self) -> i32 {
        self.chip().active_priority()
    }

    /// The pending and enabled exception of the highest priority above `exec`, if any.
    pub(super) fn pending_over(&self, exec: i32) -> Option<u32> {
        let c = self.chip();
        let mut best: Option<(i32, u32)> = None;
        for n in 2..c.core.pending.len() as u32 {
            if !c.core.pending[n as usize] {
                continue;
            }
            if n >= exc::IRQ0 && !c.core.enabled[(n - exc::IRQ0) as usize] {
                continue;
            }
            let p = c.core.group_priority(n);
            if p < exec && best.is_none_or(|(bp, _)| p < bp) {
                best = Some((p, n));
            }
        }
        best.map(|(_, n)| n)
    }

    /// The pending exception to take now, if any.
    pub(super) fn exception_to_take(&self) -> Option<u32> {
        self.pending_above(true)
    }

    /// Whether a pending interrupt wakes a WFE/WFI (PRIMASK ignored).
    pub(super) fn wakes(&self) -> bool {
        self.pending_above(false).is_some()
    }

    /// Enters exception `n` at the current instruction boundary (`ret` the return address).
    pub(super) fn enter(&mut self, n: u32, ret: u32) -> Result<(), String> {
        if let Some((e, late, left)) = self.chip().inject.late_entry
            && e == n
            && left > 0
        {
            // Held off (`start_late`): the time passes in the context it preempts.
            let c = self.chip_mut();
            c.add_cycles(late);
            c.inject.late_entry = Some((e, late, left - 1));
        }
        let control = self.reg(R::CONTROL);
        let fpca = control & 4 != 0;
        let sp = self.reg(R::SP);
        let frame: u32 = if fpca { 0x68 } else { 0x20 };
        let realign = (sp - frame) & 4 != 0;
        let new_sp = (sp - frame) & !7;
        // The xPSR stacked with its IT bits (B1.5.6): the engine reads them as zero there.
        let xpsr = with_it(self.reg(R::XPSR), self.it_state());
        let regs = [
            self.reg(R::R0),
            self.reg(R::R1),
            self.reg(R::R2),
            self.reg(R::R3),
            self.reg(R::R12),
            self.reg(R::LR),
            ret,
            (xpsr & !0x1FF & !(1 << 9)) | if realign { 1 << 9 } else { 0 } | (1 << 24),
        ];
        let mut bytes = Vec::with_capacity(frame as usize);
        for r in regs {
            bytes.extend_from_slice(&r.to_le_bytes());
        }
        if fpca {
            for k in 0..16 {
                let s = self.uc.reg_read(reg_s(k)).map_err(err)? as u32;
                bytes.extend_from_slice(&s.to_le_bytes());
            }
            let fpscr = self.reg(R::FPSCR);
            bytes.extend_from_slice(&fpscr.to_le_bytes());
            bytes.extend_from_slice(&0u32.to_le_bytes());
        }
        let c = self.uc.get_data();
        // A frame pushed into the guard: MemManage (MSTKERR) instead.
        let into_guard = c
            .guard
            .is_some_and(|(g, len)| new_sp < g + len && new_sp + frame > g);
        let to_thread = c.active.is_empty();
        if into_guard {
            let c = self.uc.get_data_mut();
            c.guard_hit.get_or_insert(new_sp);
            c.core.cfsr |= 1 << 4; // MSTKERR
        }
        if self.uc.mem_write(new_sp as u64, &bytes).is_err() {
            return Err(format!(
                "exception {n}: stacking at {new_sp:#010x} outside RAM (SP {sp:#010x})"
            ));
        }
        let exc_return: u32 =
            0xFFFF_FFE1 | if fpca { 0 } else { 0x10 } | if to_thread { 8 } else { 0 };
        // VTOR 0 at reset: the boot alias of flash at 0 (BOOT0 low, RM0090 §2.4).
        let vtor = self.chip().core.vtor;
        let vtor = if vtor < FLASH as u32 {
            vtor + FLASH as u32
        } else {
            vtor
        };
        let handler = self.read_u32(vtor + 4 * n)?;
        self.uc.reg_write(R::SP, new_sp as u64).map_err(err)?;
        self.uc.reg_write(R::LR, exc_return as u64).map_err(err)?;
        // Clear the IT bits, keep the flags; T set.
        self.uc
            .reg_write(R::XPSR, ((xpsr & 0xF80F_0000) | (1 << 24)) as u64)
            .map_err(err)?;
        self.set_it_state(0)?;
        if fpca {
            self.uc
                .reg_write(R::CONTROL, (control & !4) as u64)
                .map_err(err)?;
        }
        self.uc
            .reg_write(R::PC, (handler & !1) as u64)
            .map_err(err)?;
        let c = self.uc.get_data_mut();
        c.core.pending[n as usize] = false;
        let at = c.cycles;
        c.active.push(Active {
            exc: n,
            instructions: 0,
            cycles: 0,
            at,
        });
        c.core.vect_active = n;
        c.event = true;
        // Exception entry: 12 cycles (PM0214 §2.3.7); the FP frame stacked at entry (29), or
        // lazily at the handler's first FP instruction with the M4's costs.
        let entry = match c.model {
            TimeModel::Cpi(_) => {
                if fpca {
                    29
                } else {
                    12
                }
            }
            TimeModel::Cycles => c.timing.enter(fpca) as u64,
        };
        c.add_cycles(entry);
        Ok(())
    }

    /// Returns from the active exception with `exc_return` (B1.5.8).
    pub(super) fn exception_return(&mut self, exc_return: u32) -> Result<(), String> {
        let Some(mut done) = self.uc.get_data_mut().active.pop() else {
            return Err(format!(
                "exception return ({exc_return:#010x}) with no exception active"
            ));
        };
        let fp = exc_return & 0x10 == 0;
        let sp = self.reg(R::SP);
        let frame: u32 = if fp { 0x68 } else { 0x20 };
        let mut bytes = vec![0u8; frame as usize];
        self.uc.mem_read(sp as u64, &mut bytes).map_err(err)?;
        let w = |k: usize| u32::from_le_bytes(bytes[4 * k..4 * k + 4].try_into().unwrap());
        for (k, r) in [R::R0, R::R1, R::R2, R::R3, R::R12, R::LR]
            .into_iter()
            .enumerate()
        {
            self.uc.reg_write(r, w(k) as u64).map_err(err)?;
        }
        let pc = w(6);
        let xpsr = w(7);
        if fp {
            for k in 0..16 {
                self.uc.reg_write(reg_s(k), w(8 + k) as u64).map_err(err)?;
            }
            self.uc.reg_write(R::FPSCR, w(24) as u64).map_err(err)?;
        }
        let control = self.reg(R::CONTROL);
        let control = if fp { control | 4 } else { control & !4 };
        self.uc.reg_write(R::CONTROL, control as u64).map_err(err)?;
        let new_sp = sp + frame + if xpsr & (1 << 9) != 0 { 4 } else { 0 };
        self.uc.reg_write(R::SP, new_sp as u64).map_err(err)?;
        self.uc
            .reg_write(R::XPSR, ((xpsr & !0x1FF & !(1 << 9)) | (1 << 24)) as u64)
            .map_err(err)?;
        // The IT bits back (the engine keeps them in its CPSR), and where the run goes on.
        let it = it_of(xpsr);
        self.set_it_state(it)?;
        self.uc.reg_write(R::PC, (pc & !1) as u64).map_err(err)?;
        let c = self.uc.get_data_mut();
        (c.prev_end, c.it_next) = ((pc & !1) as u64, it);
        c.core.vect_active = c.active.last().map_or(0, |a| a.exc);
        c.event = true;
        let ret = match c.model {
            TimeModel::Cpi(_) => 10,
            TimeModel::Cycles => c.timing.exit() as u64,
        };
        c.cycles += ret;
        done.cycles += ret;
        if c.profile_exc == Some(done.exc) {
            let blocks = std::mem::take(&mut c.run_blocks);
            if done.cycles > c.profile_over
                && let Some(p) = c.profile.as_mut()
            {
                for (a, n, cycles) in blocks {
                    let e = p.entry(a).or_insert((0, 0));
                    (e.0, e.1) = (e.0 + n as u64, e.1 + cycles);
                }
            }
        }
        self.handled.push(Handled {
            exc: done.exc,
            instructions: done.instructions,
            cycles: done.cycles,
            at: done.at,
        });
        Ok(())
    }

    /// A synchronous fault at `pc`: MemManage/BusFault/UsageFault when enabled and above
    /// the execution priority, else HardFault (escalation, B1.5.5); a HardFault that cannot
    /// be taken is a lockup.
    pub(super) fn fault(&mut self, kind: u32, pc: u32, why: &str) -> Result<(), Stop> {
        let t = self.seconds();
        self.faults
            .push(format!("{t:.6} s: fault {kind} at {pc:#010x}: {why}"));
        let exec = self.execution_priority(true);
        let c = self.chip();
        let n = if c.core.fault_enabled(kind) && c.core.group_priority(kind) < exec {
            kind
        } else {
            exc::HARD_FAULT
        };
        if n == exc::HARD_FAULT {
            if exec <= -1 {
                return Err(Stop::Lockup(format!("lockup at {pc:#010x}: {why}")));
            }
            self.chip_mut().core.hfsr |= 1 << 30; // FORCED
        }
        self.enter(n, pc).map_err(Stop::Lockup)
    }
}
