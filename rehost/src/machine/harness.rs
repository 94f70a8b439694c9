//! What a bench (and the tests) do to the emulated board: faults injected (the HSE, a hung
//! handler, a late interrupt, an encoder jump, the flash image), the link driven line by line,
//! power cycles, and the measurements read back (profiles by function, cycles of a handler's
//! runs, the stack's depth).

use super::*;

impl Machine {
    /// The HSE fails for good (RM0090 §6.2.7): with the clock security system on, CSSF and
    /// the NMI, the HSE off and the system clock switched back to the HSI (RCC_CFGR.SWS = 00);
    /// after a reset it never becomes ready again; the failure event at TIM8's break input
    /// ([`tim::Timer::clock_failure`]). (The model keeps the core's time at 168 MHz.)
    pub fn hse_fails(&mut self) {
        let c = self.chip_mut();
        c.p.rcc.hse_dead = true;
        let cr = c.p.rcc.read(0x00);
        if cr & (1 << 19) == 0 {
            return;
        }
        c.p.rcc.write(0x00, cr & !(1 << 16));
        let cfgr = c.p.rcc.read(0x08);
        c.p.rcc.write(0x08, cfgr & !3);
        c.p.rcc.css_fired();
        // The failure event at TIM8's break input (RM0090 §7.2.7), then the NMI.
        c.p.tim8.clock_failure();
        c.core.pending[2] = true;
        c.stop_soon();
    }

    /// Whether the image's loadable segments touch flash bytes `offset..offset + len`
    /// (offsets from the flash's start).
    pub fn image_covers(&self, offset: u32, len: u32) -> bool {
        let (a, b) = (FLASH + offset as u64, FLASH + offset as u64 + len as u64);
        self.segments
            .iter()
            .any(|(at, data)| *at < b && at + data.len() as u64 > a)
    }

    /// The flash's contents now (the image and what it stored).
    pub fn flash(&self) -> Result<Vec<u8>, String> {
        let mut b = vec![0u8; self.board.flash_size() as usize];
        self.uc.mem_read(FLASH, &mut b).map_err(err)?;
        Ok(b)
    }

    /// Puts the flash back to `bytes` (from [`Machine::flash`]): the 4 KiB pages that differ
    /// are written and their translated code dropped.
    pub fn set_flash(&mut self, bytes: &[u8]) -> Result<(), String> {
        let now = self.flash()?;
        if bytes.len() != now.len() {
            return Err(format!("{} bytes of flash, not {}", now.len(), bytes.len()));
        }
        for (k, (a, b)) in now.chunks(4096).zip(bytes.chunks(4096)).enumerate() {
            if a != b {
                let at = FLASH + (k * 4096) as u64;
                self.uc.mem_write(at, b).map_err(err)?;
                self.uc
                    .ctl_remove_cache(at, at + b.len() as u64)
                    .map_err(err)?;
            }
        }
        Ok(())
    }

    /// Exception `exc`'s handler hangs from its first instruction (a `b .` patched over it
    /// until the next reset): a control step that never ends, for the deadman.
    pub fn hang_handler(&mut self, exc: u32) -> Result<(), String> {
        let addr = (self.read_u32(self.vector_table + 4 * exc)? & !1) as u64;
        let mut orig = [0u8; 2];
        self.uc.mem_read(addr, &mut orig).map_err(err)?;
        // B . (T1 encoding, offset -4 from PC: itself).
        self.uc.mem_write(addr, &[0xFE, 0xE7]).map_err(err)?;
        self.uc.ctl_remove_cache(addr, addr + 2).map_err(err)?;
        let c = self.chip_mut();
        c.inject.patches.push((addr, orig));
        c.stop_soon();
        Ok(())
    }

    /// Exception `exc`'s next `runs` entries each come `cycles` late, as if something above
    /// it had held it off that long (the time passes in the context it preempts): a control
    /// step that starts late, for the deadline.
    pub fn start_late(&mut self, exc: u32, cycles: u64, runs: u32) {
        self.chip_mut().inject.late_entry = Some((exc, cycles, runs));
    }

    /// The encoder jumps by `counts` (a burst of noise counted as edges).
    pub fn encoder_jump(&mut self, counts: i32) {
        let c = self.chip_mut();
        c.enc_offset = c.enc_offset.wrapping_add(counts as u32);
        c.stop_soon();
    }

    /// Bytes for the image's link: USART2's receive line (the Nucleo), the USB host's bulk
    /// OUT stream (the F405).
    pub fn send_to_image(&mut self, bytes: &[u8]) {
        let usb = self.board == Board::F405;
        let c = self.chip_mut();
        let now = c.cycles;
        if usb {
            c.p.usb_host.from_host.extend(bytes);
            c.p.usb_host.kick(now);
            c.stop_soon();
        } else {
            c.p.usart2.from_host.extend(bytes);
            c.p.usart2.poll_host(now);
        }
    }

    /// Bytes for the image's link, the one at `bad` (an index into `bytes`) arriving with a
    /// framing error (noise on the line).
    pub fn send_damaged_to_image(&mut self, bytes: &[u8], bad: usize) {
        let c = self.chip_mut();
        let u = &mut c.p.usart2;
        let n = u.received + u.from_host.len() as u64 + bad as u64;
        u.framing_errors.insert(n);
        self.send_to_image(bytes);
    }

    /// Bytes the image sent on its link since the last call.
    pub fn take_from_image(&mut self) -> Vec<u8> {
        if self.board == Board::F405 {
            std::mem::take(&mut self.chip_mut().p.usb_host.to_host)
        } else {
            std::mem::take(&mut self.chip_mut().p.usart2.to_host)
        }
    }

    /// The link ready for requests within `seconds` of device time: the F405's USB
    /// enumerated by the emulated host and its port opened (DTR up; an error names what the
    /// host found wrong); the Nucleo's UART is always ready.
    pub fn link_ready(&mut self, seconds: f64) -> Result<(), String> {
        use crate::periph::usb_host::Link;
        if self.board != Board::F405 {
            return Ok(());
        }
        let (h, _, now) = self.usb();
        h.open_port(now);
        let until = self.seconds() + seconds;
        let open = |m: &Machine| m.usb_host().link == Link::Open && m.usb_host().dtr;
        while !open(self) && self.seconds() < until {
            self.run_for(0.001).map_err(|e| format!("{e:?}"))?;
        }
        let h = self.usb_host();
        if !h.errors.is_empty() {
            return Err(format!("the USB host: {}", h.errors.join("; ")));
        }
        if !open(self) {
            return Err(format!(
                "the USB host did not open the port within {seconds} s: {:?}, DTR {}",
                h.link, h.dtr
            ));
        }
        Ok(())
    }

    /// The USB host (the F405's link): its state, the descriptors it read, its errors.
    pub fn usb_host(&self) -> &crate::periph::usb_host::Host {
        &self.chip().p.usb_host
    }

    /// The USB host to act on (pull the cable, stop reading, a class request), and the device
    /// it talks to.
    pub fn usb(
        &mut self,
    ) -> (
        &mut crate::periph::usb_host::Host,
        &mut crate::periph::otg::OtgFs,
        u64,
    ) {
        let c = self.chip_mut();
        c.stop_soon();
        let now = c.cycles;
        let p = &mut c.p;
        (&mut p.usb_host, &mut p.otg, now)
    }

    /// Whether a log line containing `text` has come.
    pub fn logged(&self, text: &str) -> bool {
        self.log_lines.iter().any(|l| l.text.contains(text))
    }

    /// The deepest stack so far \[bytes\] below the top of RAM.
    pub fn stack_depth(&self) -> u32 {
        let top = self.read_u32(self.vector_table).unwrap_or(0);
        top.saturating_sub(self.chip().sp_min)
    }
}

impl Machine {
    /// Sends `line` on the link and runs until its reply ends (a line `ok…` or `err…`;
    /// telemetry lines, `#…`, are left out), at most `seconds` of device time. The reply's
    /// lines, or why none came.
    pub fn request(&mut self, line: &str, seconds: f64) -> Result<Vec<String>, String> {
        let _ = self.take_from_image();
        let mut bytes = line.as_bytes().to_vec();
        bytes.push(b'\n');
        self.send_to_image(&bytes);
        let until = self.chip().cycles + (seconds * HZ as f64) as u64;
        let mut text = String::new();
        while self.chip().cycles < until {
            let slice = (self.chip().cycles + HZ / 2000).min(until);
            self.run_until(slice)
                .map_err(|e| format!("`{line}`: the image stopped: {e:?}"))?;
            text.push_str(&String::from_utf8_lossy(&self.take_from_image()));
            let lines: Vec<String> = text
                .lines()
                .filter(|l| !l.starts_with('#'))
                .map(str::to_string)
                .collect();
            if text.ends_with('\n')
                && lines
                    .last()
                    .is_some_and(|l| l.starts_with("ok") || l.starts_with("err"))
            {
                return Ok(lines);
            }
        }
        Err(format!(
            "`{line}`: no reply within {seconds} s of device time (got {text:?})"
        ))
    }

    /// Runs until a log line containing `text` comes, at most `seconds` of device time.
    pub fn run_until_logged(&mut self, text: &str, seconds: f64) -> Result<(), String> {
        let until = self.chip().cycles + (seconds * HZ as f64) as u64;
        let from = self.log_lines.len();
        while !self.log_lines[from..].iter().any(|l| l.text.contains(text)) {
            if self.chip().cycles >= until {
                return Err(format!("no log line {text:?} within {seconds} s"));
            }
            let slice = (self.chip().cycles + HZ / 1000).min(until);
            self.run_until(slice).map_err(|e| format!("{e:?}"))?;
        }
        Ok(())
    }

    /// A power cycle: RAM lost (filled with a pattern), flash kept, the image from reset with
    /// the RCC's power-on reset flags.
    pub fn power_cycle(&mut self) -> Result<(), String> {
        self.uc
            .mem_write(SRAM, &vec![0xA5; SRAM_LEN as usize])
            .map_err(err)?;
        let c = self.chip_mut();
        c.inject.power_lost = false;
        c.inject.cut_at_flash_write = None;
        self.system_reset(0)?;
        self.chip_mut().p.rcc.power_on();
        Ok(())
    }

    /// Starts counting instructions and cycles by function: everything the core runs, or
    /// exception `exc`'s own.
    pub fn start_profile(&mut self, exc: Option<u32>) {
        self.start_profile_over(exc, 0);
    }

    /// As [`Machine::start_profile`], only the runs of exception `exc` of more than `over`
    /// cycles (their entry and return included) counted.
    pub fn start_profile_over(&mut self, exc: Option<u32>, over: u64) {
        let c = self.chip_mut();
        c.profile = Some(HashMap::new());
        c.profile_exc = exc;
        c.profile_over = over;
        c.run_blocks.clear();
    }

    /// The instructions and cycles (blocks' own, not entry and return) counted since
    /// [`Machine::start_profile`], by function (the image's symbols), most cycles first.
    pub fn take_profile(&mut self) -> Vec<(String, u64, u64)> {
        use object::{Object, ObjectSymbol, SymbolKind};
        let Some(blocks) = self.chip_mut().profile.take() else {
            return Vec::new();
        };
        let Ok(file) = object::File::parse(&*self.image) else {
            return Vec::new();
        };
        let mut syms: Vec<(u64, u64, String)> = file
            .symbols()
            .filter(|s| s.kind() == SymbolKind::Text && s.size() > 0)
            .map(|s| {
                (
                    s.address() & !1,
                    s.size(),
                    s.name().unwrap_or("?").to_string(),
                )
            })
            .collect();
        syms.sort();
        let mut by: HashMap<String, (u64, u64)> = HashMap::new();
        for (addr, (n, cycles)) in blocks {
            let i = syms.partition_point(|s| s.0 <= addr);
            let name = i
                .checked_sub(1)
                .and_then(|i| syms.get(i))
                .filter(|s| addr < s.0 + s.1)
                .map_or_else(
                    || format!("{addr:#010x}"),
                    |s| format!("{:#}", rustc_demangle::demangle(&s.2)),
                );
            let e = by.entry(name).or_insert((0, 0));
            (e.0, e.1) = (e.0 + n, e.1 + cycles);
        }
        let mut v: Vec<(String, u64, u64)> = by.into_iter().map(|(f, (n, c))| (f, n, c)).collect();
        v.sort_by_key(|e| std::cmp::Reverse(e.2));
        v
    }

    /// The image's function at `addr` (its symbol), or the address.
    pub fn symbol_at(&self, addr: u64) -> String {
        use object::{Object, ObjectSymbol, SymbolKind};
        let Ok(file) = object::File::parse(&*self.image) else {
            return format!("{addr:#010x}");
        };
        file.symbols()
            .filter(|s| s.kind() == SymbolKind::Text)
            .find(|s| (s.address() & !1) <= addr && addr < (s.address() & !1) + s.size())
            .and_then(|s| s.name().ok())
            .map_or_else(
                || format!("{addr:#010x}"),
                |n| format!("{:#}", rustc_demangle::demangle(n)),
            )
    }

    /// A what-if for the cycle model: the functions whose demangled names contain one of
    /// `names` fetched as from SRAM through the I-bus (no flash wait states, the accelerator
    /// untouched), as if the image had placed them there; the code itself stays where it is.
    /// Returns each function taken (name, bytes). Error: a name that matches nothing.
    pub fn fetch_as_sram(&mut self, names: &[String]) -> Result<Vec<(String, u32)>, String> {
        use object::{Object, ObjectSymbol, SymbolKind};
        let file = object::File::parse(&*self.image).map_err(|e| format!("the image: {e}"))?;
        let mut taken = Vec::new();
        let mut ranges = Vec::new();
        for want in names {
            let before = taken.len();
            for s in file.symbols().filter(|s| s.kind() == SymbolKind::Text) {
                let Ok(n) = s.name() else { continue };
                let name = format!("{:#}", rustc_demangle::demangle(n));
                let from = (s.address() & !1) as u32;
                if name.contains(want.as_str())
                    && s.size() > 0
                    && !ranges.iter().any(|&(f, _)| f == from)
                {
                    ranges.push((from, from + s.size() as u32));
                    taken.push((name, s.size() as u32));
                }
            }
            if taken.len() == before {
                return Err(format!(
                    "--what-if-sram {want}: no function of the image matches"
                ));
            }
        }
        self.chip_mut().timing.art.sram_code = ranges;
        Ok(taken)
    }

    /// Cycles (entry and return included) of every run of exception `exc` entered at or after
    /// `from` \[cycles\].
    pub fn cycles_of(&self, exc: u32, from: u64) -> Vec<u64> {
        self.handled
            .iter()
            .filter(|h| h.exc == exc && h.at >= from)
            .map(|h| h.cycles)
            .collect()
    }
}
