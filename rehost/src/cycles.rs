//! The Cortex-M4's cycles: what each instruction costs by its class, what a taken branch adds,
//! what the flash's wait states add behind the ART accelerator, and what exception entry and
//! return cost. The emulated time (timers, ADC, UART, DMA) runs on these cycles.
//!
//! Sources:
//! - Cortex-M4 TRM (ARM DDI 0439B, r0p1), §3.3.1 *Cortex-M4 instructions* (Table 3-1, the
//!   processor instruction timings) and §7.2.3 *FPU instruction set* (Table 7-1): data
//!   processing and MUL/MLA 1; SDIV/UDIV 2-12; LDR/STR 2, a load or store that follows another
//!   pipelines to 1; LDRD/STRD 3; LDM/STM/PUSH/POP 1+N; a branch 1, +P when taken (P, the
//!   pipeline refill, 1-3); TBB/TBH 2+P; VADD/VMUL/VCVT/VMOV 1; VMLA/VFMA and their negations
//!   3; VDIV/VSQRT 14; VLDR/VSTR 2; VLDM/VSTM/VPUSH/VPOP 1+N.
//! - Cortex-M4 TRM §5.5 (*Exception entry and return*) and the ARMv7-M ARM B1.5.6-7: entry 12
//!   cycles (the basic frame stacked), return about 10 (10 is counted), a tail-chain 6; with
//!   lazy FP stacking (FPCCR.LSPEN, on from reset) the extended frame's S0-S15 and FPSCR (18
//!   words with the reserved one) are stacked at the handler's first FP instruction, not at
//!   entry, and unstacked at return.
//! - RM0090 §3.5.1 (Table 10: 5 wait states at 150-168 MHz, 2.7-3.6 V) and §3.5.2 (the ART
//!   accelerator: an instruction cache of 64 lines of 128 bits, a data cache of 8 lines, the
//!   prefetch of the next sequential 128-bit line); RM0390 §3.4 is the F446's same
//!   accelerator. FLASH_ACR (RM0090 §3.9.1): LATENCY bits 3:0, PRFTEN bit 8, ICEN bit 9,
//!   DCEN bit 10.
//!
//! Not modelled, and how large they are judged (docs/rehost.md): the bus matrix's contention
//! (the DMA's reads of the ADC and the USART against the core's loads: a cycle now and then,
//! under 1 % of a period); the write buffer (a store to a peripheral completes behind later
//! instructions: counted at its full 2 cycles, an overestimate of up to a cycle per store);
//! a taken branch's refill P counted as [`REFILL`] whatever the target's width and alignment
//! (±1 a branch); SDIV/UDIV counted at their worst, [`DIVIDE`] (they end early on small
//! quotients); the IT instruction counted as 1 (the core folds some); a flash line fetched by
//! the prefetch while a data read of flash is in progress.

/// A taken branch's pipeline refill \[cycles\] (the TRM's P, 1-3; 2 counted).
pub const REFILL: u32 = 2;

/// SDIV/UDIV \[cycles\]: the TRM's 2-12, counted at their worst.
pub const DIVIDE: u32 = 12;

/// Exception entry \[cycles\]: the basic frame stacked, the vector fetched.
pub const ENTRY: u32 = 12;

/// Exception return \[cycles\].
pub const RETURN: u32 = 10;

/// Lazy FP stacking \[cycles\]: S0-S15, FPSCR and the reserved word (18 words) stacked at the
/// handler's first FP instruction when the interrupted context had FP state (CONTROL.FPCA),
/// and as many to unstack them at return.
pub const FP_FRAME: u32 = 18;

/// An instruction's timing class (TRM Table 3-1 and Table 7-1).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Class {
    /// Data processing, moves, compares, shifts, MUL/MLA/MLS, long multiplies, IT, hints,
    /// MSR/MRS, barriers, CPS: 1.
    Alu,
    /// A single load or store (LDR/STR of a byte, halfword or word; LDREX/STREX; PLD): 2, or
    /// 1 when it follows another.
    LoadStore,
    /// LDRD/STRD: 3.
    Dual,
    /// LDM/STM/PUSH/POP of this many registers: 1+N.
    Multiple(u8),
    /// VLDR/VSTR: 2.
    FpLoadStore,
    /// VLDM/VSTM/VPUSH/VPOP of this many words: 1+N.
    FpMultiple(u8),
    /// VMLA/VMLS/VNMLA/VNMLS/VFMA/VFMS/VFNMA/VFNMS: 3.
    FpMac,
    /// VDIV/VSQRT: 14.
    FpDivSqrt,
    /// Other FP data processing and transfers (VADD, VMUL, VCVT, VCMP, VMOV, VMRS): 1.
    Fp,
    /// SDIV/UDIV: [`DIVIDE`].
    Divide,
    /// B, BL, BX, BLX, CBZ/CBNZ: 1, + [`REFILL`] when taken.
    Branch,
    /// TBB/TBH: 2, + [`REFILL`] (always taken).
    TableBranch,
}

impl Class {
    /// Whether it is an FP instruction (the first one in a handler stacks the lazy frame).
    pub fn is_fp(self) -> bool {
        matches!(
            self,
            Class::FpLoadStore | Class::FpMultiple(_) | Class::FpMac | Class::FpDivSqrt | Class::Fp
        )
    }
}

/// One decoded instruction: its class, its length \[bytes\] and whether it may write the PC
/// (a branch, or a load, POP, LDM, MOV or ADD into the PC).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Decoded {
    /// The timing class.
    pub class: Class,
    /// 2 or 4 \[bytes\].
    pub len: u8,
    /// Whether it may write the PC.
    pub writes_pc: bool,
}

/// Whether a first halfword starts a 32-bit instruction (ARMv7-M ARM A5.1: its top five
/// bits 0b11101, 0b11110 or 0b11111).
pub fn is_wide(hw1: u16) -> bool {
    hw1 >> 11 >= 0b11101
}

/// Decodes the instruction at `hw1` (and `hw2`, its second halfword when it is 32 bits wide)
/// into its timing class (ARMv7-M ARM A5.2 for the 16-bit encodings, A5.3 for the 32-bit
/// ones, A6.4-A6.6 for the FP ones).
pub fn decode(hw1: u16, hw2: u16) -> Decoded {
    if is_wide(hw1) {
        let (class, writes_pc) = decode32(hw1, hw2);
        Decoded {
            class,
            len: 4,
            writes_pc,
        }
    } else {
        let (class, writes_pc) = decode16(hw1);
        Decoded {
            class,
            len: 2,
            writes_pc,
        }
    }
}

/// A5.2: the 16-bit encodings.
fn decode16(hw: u16) -> (Class, bool) {
    let op = hw >> 10; // bits 15:10
    let regs8 = (hw & 0xFF).count_ones() as u8;
    match op {
        // A5.2.1 shift, add, subtract, move, compare; A5.2.2 data processing (MUL included).
        0b000000..=0b010000 => (Class::Alu, false),
        // A5.2.3 special data instructions and branch and exchange.
        0b010001 => match (hw >> 8) & 0b11 {
            0b11 => (Class::Branch, true), // BX, BLX
            0b01 => (Class::Alu, false),   // CMP (high registers)
            // ADD/MOV (high registers): into the PC when D:Rd is 15.
            _ => {
                let rd = ((hw >> 4) & 0b1000) | (hw & 0b111);
                if rd == 15 {
                    (Class::Branch, true)
                } else {
                    (Class::Alu, false)
                }
            }
        },
        // LDR (literal); A5.2.4 load/store single data item.
        0b010010..=0b100111 => (Class::LoadStore, false),
        // ADR, ADD (SP plus immediate).
        0b101000..=0b101011 => (Class::Alu, false),
        // A5.2.5 miscellaneous.
        0b101100..=0b101111 => {
            let op7 = (hw >> 5) & 0x7F; // bits 11:5
            if op7 & 0b1110000 == 0b0100000 {
                // PUSH: the list and LR (bit 8).
                (Class::Multiple(regs8 + ((hw >> 8) & 1) as u8), false)
            } else if op7 & 0b1110000 == 0b1100000 {
                // POP: the list and PC (bit 8).
                let pc = (hw >> 8) & 1 == 1;
                (Class::Multiple(regs8 + pc as u8), pc)
            } else if op7 & 0b0101000 == 0b0001000 {
                // CBZ, CBNZ (bits 11:8 = x0x1).
                (Class::Branch, true)
            } else {
                // IT and the hints, CPS, REV, SXTH and the rest.
                (Class::Alu, false)
            }
        }
        // STM, LDM.
        0b110000..=0b110011 => (Class::Multiple(regs8), false),
        // B (conditional), UDF, SVC.
        0b110100..=0b110111 => {
            let cond = (hw >> 8) & 0xF;
            if cond < 0b1110 {
                (Class::Branch, true)
            } else {
                (Class::Alu, false)
            }
        }
        // B (unconditional).
        0b111000 | 0b111001 => (Class::Branch, true),
        _ => (Class::Alu, false),
    }
}

/// A5.3: the 32-bit encodings.
fn decode32(hw1: u16, hw2: u16) -> (Class, bool) {
    let op1 = (hw1 >> 11) & 0b11;
    let op2 = (hw1 >> 4) & 0x7F;
    let rt = (hw2 >> 12) & 0xF;
    match op1 {
        0b01 => {
            if op2 & 0b1100100 == 0b0000000 {
                // A5.3.5 load/store multiple (LDM, STM, PUSH.W, POP.W): the list in hw2.
                let load = (hw1 >> 4) & 1 == 1;
                let n = hw2.count_ones() as u8;
                let pc = load && hw2 >> 15 == 1;
                (Class::Multiple(n), pc)
            } else if op2 & 0b1100100 == 0b0000100 {
                // A5.3.6 load/store dual or exclusive, table branch.
                if hw1 & 0xFFF0 == 0xE8D0 {
                    match (hw2 >> 4) & 0xF {
                        0b0000 | 0b0001 => (Class::TableBranch, true),
                        _ => (Class::LoadStore, false), // LDREXB, LDREXH
                    }
                } else if hw1 & 0xFFE0 == 0xE840 || hw1 & 0xFFF0 == 0xE8C0 {
                    // LDREX/STREX (op1 00, op2 0x), STREXB/STREXH.
                    (Class::LoadStore, false)
                } else {
                    (Class::Dual, false)
                }
            } else if op2 & 0b1100000 == 0b0100000 {
                // A5.3.11 data processing (shifted register).
                (Class::Alu, false)
            } else {
                // A5.3.18 coprocessor instructions: the FPU's.
                (coprocessor(hw1, hw2), false)
            }
        }
        0b10 => {
            if hw2 >> 15 == 0 {
                // A5.3.1, A5.3.3 data processing (immediate).
                (Class::Alu, false)
            } else {
                // A5.3.4 branches and miscellaneous control.
                match (hw2 >> 12) & 0b101 {
                    0b000 => {
                        if (hw1 >> 7) & 0b111 != 0b111 {
                            (Class::Branch, true) // B<c>.W (T3)
                        } else {
                            (Class::Alu, false) // MSR, MRS, hints, barriers
                        }
                    }
                    // B.W (T4), BL (and BLX immediate, not in ARMv7-M).
                    _ => (Class::Branch, true),
                }
            }
        }
        _ => {
            // op1 = 0b11.
            if op2 & 0b1110001 == 0b0000000 {
                // A5.3.10 store single data item.
                (Class::LoadStore, false)
            } else if op2 & 0b1100111 == 0b0000001 || op2 & 0b1100111 == 0b0000011 {
                // A5.3.9, A5.3.8 load byte, halfword (and the preload hints).
                (Class::LoadStore, false)
            } else if op2 & 0b1100111 == 0b0000101 {
                // A5.3.7 load word: LDR into the PC is a branch.
                (Class::LoadStore, rt == 15)
            } else if op2 & 0b1110000 == 0b0100000 {
                // A5.3.12 data processing (register).
                (Class::Alu, false)
            } else if op2 & 0b1111000 == 0b0110000 {
                // A5.3.16 multiply, multiply accumulate.
                (Class::Alu, false)
            } else if op2 & 0b1111000 == 0b0111000 {
                // A5.3.17 long multiply, divide: SDIV (op1 001), UDIV (op1 011).
                match op2 & 0b111 {
                    0b001 | 0b011 => (Class::Divide, false),
                    _ => (Class::Alu, false),
                }
            } else if op2 & 0b1000000 == 0b1000000 {
                (coprocessor(hw1, hw2), false)
            } else {
                (Class::Alu, false)
            }
        }
    }
}

/// A5.3.18 with A6.4-A6.6: the FPU's instructions (coprocessors 10 and 11).
fn coprocessor(hw1: u16, hw2: u16) -> Class {
    let coproc = (hw2 >> 8) & 0xF;
    if coproc & 0b1110 != 0b1010 {
        return Class::Alu;
    }
    let op1 = (hw1 >> 4) & 0x3F; // bits 25:20
    if op1 & 0b100000 == 0 {
        if op1 & 0b111010 == 0b000000 {
            // 64-bit transfers between core and extension registers (VMOV), or undefined.
            return Class::Fp;
        }
        // A6.5 extension register load/store: P (bit 24), W (bit 21).
        let p = (hw1 >> 8) & 1 == 1;
        let w = (hw1 >> 5) & 1 == 1;
        if p && !w {
            // VLDR, VSTR.
            Class::FpLoadStore
        } else {
            // VLDM, VSTM, VPUSH, VPOP: imm8 words.
            Class::FpMultiple((hw2 & 0xFF) as u8)
        }
    } else if op1 & 0b110000 == 0b100000 && (hw2 >> 4) & 1 == 0 {
        // A6.4 FP data processing: opc1 (bits 23, 21, 20), opc2 (bits 19:16), opc3 (7:6).
        let opc1 = ((hw1 >> 4) & 0b1011) as u8;
        let opc2 = hw1 & 0xF;
        let opc3 = (hw2 >> 6) & 0b11;
        match opc1 {
            0b0000 | 0b0001 | 0b1001 | 0b1010 => Class::FpMac,
            0b1000 => Class::FpDivSqrt,
            0b1011 if opc2 == 0b0001 && opc3 == 0b11 => Class::FpDivSqrt,
            _ => Class::Fp,
        }
    } else {
        // A6.6 8, 16 and 32-bit transfers (VMOV, VMRS, VMSR).
        Class::Fp
    }
}

/// What a straight run of instructions (an engine's block) costs before the memory system.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Block {
    /// Its length \[bytes\].
    pub bytes: u32,
    /// Instructions.
    pub instructions: u32,
    /// Their cycles without branches taken or wait states \[cycles\].
    pub cycles: u32,
    /// The last instruction may write the PC: a next block that does not follow on is a
    /// taken branch.
    pub ends_in_branch: bool,
    /// It holds an FP instruction.
    pub fp: bool,
    /// The 128-bit flash lines its code spans, in order, with the cycles its instructions
    /// take in each (an instruction that straddles two lines counted in the first).
    pub lines: Vec<(u32, u32)>,
    /// The addresses its PC-relative loads read (literal pools: LDR, LDRB/H, LDRSB/H and
    /// VLDR from `[pc, #imm]`), in order.
    pub literals: Vec<u32>,
    /// Its last IT instruction's ITSTATE (firstcond:mask) and the instructions after it.
    pub last_it: Option<(u8, u32)>,
}

/// ITSTATE after one instruction of an IT block (ARMv7-M ARM A7.3.3, `ITAdvance`).
pub fn it_advance(it: u8) -> u8 {
    if it & 0x7 == 0 {
        0
    } else {
        (it & 0xE0) | ((it << 1) & 0x1F)
    }
}

impl Block {
    /// ITSTATE after the block ran, from `start` (the state it began in: 0 unless the engine
    /// split an IT block there).
    pub fn it_after(&self, start: u8) -> u8 {
        let (mut it, n) = match self.last_it {
            Some((v, n)) => (v, n),
            None => (start, self.instructions),
        };
        for _ in 0..n {
            if it == 0 {
                break;
            }
            it = it_advance(it);
        }
        it
    }
}

/// The address a PC-relative load at `at` reads, if the instruction is one (ARMv7-M ARM
/// A7.7.43 LDR (literal) T1/T2, A7.7.47/56/62/66 the byte, halfword and signed forms, A7.7.229
/// VLDR: Align(PC, 4) ± the offset, PC being the instruction's address + 4).
pub fn literal(at: u32, hw1: u16, hw2: u16) -> Option<u32> {
    let base = at.wrapping_add(4) & !3;
    if !is_wide(hw1) {
        return (hw1 >> 11 == 0b01001).then(|| base.wrapping_add(((hw1 & 0xFF) as u32) << 2));
    }
    let up = (hw1 >> 7) & 1 == 1;
    let off = if hw1 & 0xFE1F == 0xF81F {
        (hw2 & 0xFFF) as u32
    } else if hw1 & 0xFF3F == 0xED1F {
        ((hw2 & 0xFF) as u32) << 2
    } else {
        return None;
    };
    Some(if up {
        base.wrapping_add(off)
    } else {
        base.wrapping_sub(off)
    })
}

/// The cost of one instruction of `class` following one of `prev` \[cycles\].
pub fn cost(class: Class, prev: Option<Class>) -> u32 {
    match class {
        Class::Alu | Class::Fp | Class::Branch => 1,
        Class::LoadStore => {
            if prev == Some(Class::LoadStore) {
                1
            } else {
                2
            }
        }
        Class::Dual => 3,
        Class::Multiple(n) | Class::FpMultiple(n) => 1 + n as u32,
        Class::FpLoadStore | Class::TableBranch => 2,
        Class::FpMac => 3,
        Class::FpDivSqrt => 14,
        Class::Divide => DIVIDE,
    }
}

/// The block of `code` at `addr`: its instructions decoded and costed in order.
pub fn block(addr: u32, code: &[u8]) -> Block {
    let mut b = Block::default();
    let mut prev = None;
    let mut i = 0usize;
    while i + 1 < code.len() {
        let hw1 = u16::from_le_bytes([code[i], code[i + 1]]);
        let hw2 = if i + 3 < code.len() {
            u16::from_le_bytes([code[i + 2], code[i + 3]])
        } else {
            0
        };
        let d = decode(hw1, hw2);
        let c = cost(d.class, prev);
        let at = addr.wrapping_add(i as u32);
        let line = at & !15;
        match b.lines.last_mut() {
            Some((l, n)) if *l == line => *n += c,
            _ => b.lines.push((line, c)),
        }
        // A wide instruction whose second halfword is in the next line needs that line too.
        let end_line = at.wrapping_add(d.len as u32 - 1) & !15;
        if end_line != line {
            b.lines.push((end_line, 0));
        }
        if let Some(lit) = literal(at, hw1, hw2) {
            b.literals.push(lit);
        }
        // IT (A7.7.38): 0xBF, firstcond:mask with a mask (0xBFx0 are the hints).
        if d.len == 2 && hw1 >> 8 == 0xBF && hw1 & 0xF != 0 {
            b.last_it = Some(((hw1 & 0xFF) as u8, 0));
        } else if let Some((_, n)) = b.last_it.as_mut() {
            *n += 1;
        }
        b.instructions += 1;
        b.cycles += c;
        b.fp |= d.class.is_fp();
        b.ends_in_branch = d.writes_pc;
        prev = Some(d.class);
        i += d.len as usize;
    }
    b.bytes = i as u32;
    b
}

/// Whether `addr` is in the main flash (behind the ART accelerator; 0x0800_0000, up to
/// 1 MiB on the F405, 512 KiB on the F446).
pub fn in_flash(addr: u32) -> bool {
    (0x0800_0000..0x0810_0000).contains(&addr)
}

/// A least-recently-used set of 128-bit lines.
#[derive(Debug, Clone)]
struct Lines {
    cap: usize,
    /// Most recent last.
    lines: Vec<u32>,
}

impl Lines {
    fn new(cap: usize) -> Lines {
        Lines {
            cap,
            lines: Vec::with_capacity(cap),
        }
    }

    /// Whether `line` is held; it is then the most recent, and otherwise it is put in (the
    /// least recent out when full).
    fn touch(&mut self, line: u32) -> bool {
        if let Some(k) = self.lines.iter().rposition(|&l| l == line) {
            let l = self.lines.remove(k);
            self.lines.push(l);
            true
        } else {
            if self.lines.len() == self.cap {
                self.lines.remove(0);
            }
            self.lines.push(line);
            false
        }
    }

    fn clear(&mut self) {
        self.lines.clear();
    }
}

/// What the accelerator saw \[-\], and the cycles it stalled the core \[cycles\].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ArtStats {
    /// Instruction-line hits and misses (a line prefetched in time counts as a hit).
    pub i_hits: u64,
    /// Instruction-line misses.
    pub i_misses: u64,
    /// Data-line hits (literal pools and constants read from flash).
    pub d_hits: u64,
    /// Data-line misses.
    pub d_misses: u64,
    /// Cycles the core waited on the flash.
    pub stall: u64,
}

/// The flash's wait states behind the ART accelerator (RM0090 §3.5.2), as FLASH_ACR sets
/// them.
#[derive(Debug, Clone)]
pub struct Art {
    /// Wait states (FLASH_ACR.LATENCY).
    pub wait_states: u32,
    /// The prefetch of the next sequential line (PRFTEN).
    pub prefetch: bool,
    /// The instruction cache (ICEN).
    pub icache: bool,
    /// The data cache (DCEN).
    pub dcache: bool,
    /// Code taken as fetched from SRAM through the I-bus (SYSCFG's remap of SRAM1 at 0,
    /// RM0090 §9.2.1), not from the flash: no wait states and no accelerator lines
    /// (\[start, end) addresses; a what-if, `rehost check --what-if-sram`).
    pub sram_code: Vec<(u32, u32)>,
    ilines: Lines,
    dlines: Lines,
    /// The last line fetched, and the cycles its instructions took.
    last: Option<(u32, u32)>,
    /// What it saw.
    pub stats: ArtStats,
}

impl Art {
    /// The accelerator as FLASH_ACR `acr` sets it (reset: 0 wait states, everything off).
    pub fn new(acr: u32) -> Art {
        let mut a = Art {
            wait_states: 0,
            prefetch: false,
            icache: false,
            dcache: false,
            sram_code: Vec::new(),
            ilines: Lines::new(64),
            dlines: Lines::new(8),
            last: None,
            stats: ArtStats::default(),
        };
        a.configure(acr);
        a
    }

    /// FLASH_ACR written: LATENCY (bits 3:0), PRFTEN (8), ICEN (9), DCEN (10); ICRST (11) and
    /// DCRST (12) empty the caches.
    pub fn configure(&mut self, acr: u32) {
        self.wait_states = acr & 0xF;
        self.prefetch = acr & (1 << 8) != 0;
        self.icache = acr & (1 << 9) != 0;
        self.dcache = acr & (1 << 10) != 0;
        if acr & (1 << 11) != 0 {
            self.ilines.clear();
        }
        if acr & (1 << 12) != 0 {
            self.dlines.clear();
        }
    }

    /// The cycles the core waits for `b`'s code, fetched from `addr`'s memory; `jumped`: it
    /// was reached by a jump (a taken branch, an exception), not by running on from the
    /// block before \[cycles\]. A line held in the cache costs nothing; the next sequential
    /// line, with the prefetch on, what its fetch (wait states + 1) takes beyond the cycles
    /// the line before it ran; any other line the wait states.
    pub fn fetch(&mut self, addr: u32, b: &Block, jumped: bool) -> u32 {
        let in_sram = self
            .sram_code
            .iter()
            .any(|&(from, to)| (from..to).contains(&addr));
        if in_sram || !in_flash(addr) || self.wait_states == 0 {
            self.last = None;
            return 0;
        }
        let mut stall = 0;
        for (k, &(line, cycles)) in b.lines.iter().enumerate() {
            let run_on = !(k == 0 && jumped);
            let s = match self.last {
                // Still in the line being executed.
                Some((l, _)) if l == line => 0,
                _ => {
                    let cached = self.icache && self.ilines.touch(line);
                    if cached {
                        0
                    } else {
                        match self.last {
                            Some((l, ran)) if run_on && self.prefetch && l + 16 == line => {
                                (self.wait_states + 1).saturating_sub(ran)
                            }
                            _ => self.wait_states,
                        }
                    }
                }
            };
            if s == 0 {
                self.stats.i_hits += 1;
            } else {
                self.stats.i_misses += 1;
            }
            stall += s;
            self.last = Some((line, cycles));
        }
        self.stats.stall += stall as u64;
        stall
    }

    /// The cycles a data read of flash at `addr` waits (literal pools, constants) \[cycles\].
    pub fn read(&mut self, addr: u32) -> u32 {
        if !in_flash(addr) || self.wait_states == 0 {
            return 0;
        }
        let hit = self.dcache && self.dlines.touch(addr & !15);
        if hit {
            self.stats.d_hits += 1;
            0
        } else {
            self.stats.d_misses += 1;
            self.stats.stall += self.wait_states as u64;
            self.wait_states
        }
    }
}

/// An exception's frame, for lazy FP stacking.
#[derive(Debug, Clone, Copy)]
struct Frame {
    /// The interrupted context had FP state: the extended frame is reserved, its FP part
    /// stacked at the handler's first FP instruction.
    lazy: bool,
    /// The FP part was stacked (and is unstacked at return).
    stacked: bool,
}

/// The core's timing: blocks entered one after another, exceptions entered and returned, the
/// flash behind the accelerator.
#[derive(Debug, Clone)]
pub struct Timing {
    /// The accelerator.
    pub art: Art,
    /// Where the block before ended, and whether it ended in a branch.
    prev: Option<(u32, bool)>,
    /// The active exceptions' frames, innermost last.
    frames: Vec<Frame>,
    /// Cycles by what they went to \[cycles\].
    pub spent: Spent,
}

/// Where the cycles went \[cycles\].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Spent {
    /// The instructions' own cycles.
    pub instructions: u64,
    /// Taken branches' refills.
    pub branches: u64,
    /// The flash's wait states (instruction fetches and data reads).
    pub flash: u64,
    /// Exception entries and returns, with the lazy FP frames.
    pub exceptions: u64,
}

impl Spent {
    /// `o` added to these.
    pub fn add(&mut self, o: &Spent) {
        self.instructions += o.instructions;
        self.branches += o.branches;
        self.flash += o.flash;
        self.exceptions += o.exceptions;
    }

    /// All of them \[cycles\].
    pub fn total(&self) -> u64 {
        self.instructions + self.branches + self.flash + self.exceptions
    }
}

impl Timing {
    /// The timing with the accelerator as FLASH_ACR `acr` sets it.
    pub fn new(acr: u32) -> Timing {
        Timing {
            art: Art::new(acr),
            prev: None,
            frames: Vec::new(),
            spent: Spent::default(),
        }
    }

    /// The cycles of `b`, at `addr`, entered now \[cycles\]: its own, a taken branch's refill
    /// when the block before ended in a branch and `addr` does not follow it, the flash's wait
    /// for its lines, and the lazy FP frame at a handler's first FP instruction.
    pub fn block(&mut self, addr: u32, b: &Block) -> u32 {
        self.block_spent(addr, b).total() as u32
    }

    /// As [`Timing::block`], the cycles by what they went to.
    pub fn block_spent(&mut self, addr: u32, b: &Block) -> Spent {
        let jumped = self.prev.is_none_or(|(end, _)| end != addr);
        let refill = match self.prev {
            Some((end, true)) if end != addr => REFILL,
            _ => 0,
        };
        self.prev = Some((addr.wrapping_add(b.bytes), b.ends_in_branch));
        let mut wait = self.art.fetch(addr, b, jumped);
        for &lit in &b.literals {
            wait += self.art.read(lit);
        }
        let mut fp = 0;
        if b.fp
            && let Some(f) = self.frames.last_mut()
            && f.lazy
            && !f.stacked
        {
            f.stacked = true;
            fp = FP_FRAME;
        }
        let s = Spent {
            instructions: b.cycles as u64,
            branches: refill as u64,
            flash: wait as u64,
            exceptions: fp as u64,
        };
        self.spent.add(&s);
        s
    }

    /// An exception entered from a context with FP state (`fp`: CONTROL.FPCA) or without
    /// \[cycles\].
    pub fn enter(&mut self, fp: bool) -> u32 {
        self.prev = None;
        self.frames.push(Frame {
            lazy: fp,
            stacked: false,
        });
        self.spent.exceptions += ENTRY as u64;
        ENTRY
    }

    /// The innermost exception returned \[cycles\]: the return, and the FP frame's unstacking
    /// when it was stacked.
    pub fn exit(&mut self) -> u32 {
        self.prev = None;
        let fp = match self.frames.pop() {
            Some(Frame { stacked: true, .. }) => FP_FRAME,
            _ => 0,
        };
        self.spent.exceptions += (RETURN + fp) as u64;
        RETURN + fp
    }

    /// A reset: no exception active, the accelerator as FLASH_ACR's reset value sets it.
    pub fn reset(&mut self) {
        let sram_code = std::mem::take(&mut self.art.sram_code);
        *self = Timing {
            spent: self.spent,
            ..Timing::new(0)
        };
        self.art.sram_code = sram_code;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Little-endian bytes of a run of instructions given as llvm-mc printed their encodings
    /// (`llvm-mc -triple=thumbv7em-none-eabihf -mattr=+vfp4d16sp -show-encoding`).
    fn code(enc: &[&[u8]]) -> Vec<u8> {
        enc.iter().flat_map(|e| e.iter().copied()).collect()
    }

    fn class(enc: &[u8]) -> Decoded {
        let hw1 = u16::from_le_bytes([enc[0], enc[1]]);
        let hw2 = if enc.len() == 4 {
            u16::from_le_bytes([enc[2], enc[3]])
        } else {
            0
        };
        let d = decode(hw1, hw2);
        assert_eq!(d.len as usize, enc.len(), "{enc:x?}");
        d
    }

    /// Every class of the TRM's table, from an independent assembler's encodings.
    #[test]
    fn the_classes_of_the_trms_table() {
        use Class::*;
        let cases: &[(&str, &[u8], Class, bool)] = &[
            ("adds r0, r1, r2", &[0x88, 0x18], Alu, false),
            (
                "add.w r0, r1, r2, lsl #2",
                &[0x01, 0xeb, 0x82, 0x00],
                Alu,
                false,
            ),
            ("mul r0, r1, r0", &[0x01, 0xfb, 0x00, 0xf0], Alu, false),
            ("mla r0, r1, r2, r3", &[0x01, 0xfb, 0x02, 0x30], Alu, false),
            ("sdiv r0, r1, r2", &[0x91, 0xfb, 0xf2, 0xf0], Divide, false),
            ("udiv r0, r1, r2", &[0xb1, 0xfb, 0xf2, 0xf0], Divide, false),
            (
                "smull r0, r1, r2, r3",
                &[0x82, 0xfb, 0x03, 0x01],
                Alu,
                false,
            ),
            ("ldr r0, [r1]", &[0x08, 0x68], LoadStore, false),
            ("str r0, [r1, #8]", &[0x88, 0x60], LoadStore, false),
            (
                "ldr.w r0, [r1, #1024]",
                &[0xd1, 0xf8, 0x00, 0x04],
                LoadStore,
                false,
            ),
            ("ldr r0, [pc, #8]", &[0x02, 0x48], LoadStore, false),
            (
                "ldrb.w r0, [r1, r2]",
                &[0x11, 0xf8, 0x02, 0x00],
                LoadStore,
                false,
            ),
            ("strh r0, [r1, #2]", &[0x48, 0x80], LoadStore, false),
            ("ldrb r0, [r1, #1]", &[0x48, 0x78], LoadStore, false),
            ("pld [r0]", &[0x90, 0xf8, 0x00, 0xf0], LoadStore, false),
            ("ldrd r0, r1, [r2]", &[0xd2, 0xe9, 0x00, 0x01], Dual, false),
            (
                "strd r0, r1, [r2, #8]",
                &[0xc2, 0xe9, 0x02, 0x01],
                Dual,
                false,
            ),
            (
                "ldrex r0, [r1]",
                &[0x51, 0xe8, 0x00, 0x0f],
                LoadStore,
                false,
            ),
            ("push {r4-r7, lr}", &[0xf0, 0xb5], Multiple(5), false),
            ("pop {r4-r7, pc}", &[0xf0, 0xbd], Multiple(5), true),
            (
                "push.w {r4-r10, lr}",
                &[0x2d, 0xe9, 0xf0, 0x47],
                Multiple(8),
                false,
            ),
            (
                "pop.w {r4-r10, pc}",
                &[0xbd, 0xe8, 0xf0, 0x87],
                Multiple(8),
                true,
            ),
            ("ldm r0!, {r1-r3}", &[0x0e, 0xc8], Multiple(3), false),
            (
                "stm.w r0, {r1-r4}",
                &[0x80, 0xe8, 0x1e, 0x00],
                Multiple(4),
                false,
            ),
            ("ldr.w pc, [r0]", &[0xd0, 0xf8, 0x00, 0xf0], LoadStore, true),
            ("b #-4", &[0xfe, 0xe7], Branch, true),
            ("beq #-4", &[0xfe, 0xd0], Branch, true),
            ("b.w #-1000", &[0xff, 0xf7, 0x0c, 0xbe], Branch, true),
            ("beq.w #-1000", &[0x3f, 0xf4, 0x0c, 0xae], Branch, true),
            ("bl #-1000", &[0xff, 0xf7, 0x0c, 0xfe], Branch, true),
            ("bx lr", &[0x70, 0x47], Branch, true),
            ("blx r3", &[0x98, 0x47], Branch, true),
            ("cbz r0, #8", &[0x20, 0xb1], Branch, true),
            ("mov pc, r1", &[0x8f, 0x46], Branch, true),
            ("tbb [pc, r0]", &[0xdf, 0xe8, 0x00, 0xf0], TableBranch, true),
            (
                "tbh [pc, r0, lsl #1]",
                &[0xdf, 0xe8, 0x10, 0xf0],
                TableBranch,
                true,
            ),
            ("it eq", &[0x08, 0xbf], Alu, false),
            ("cpsid i", &[0x72, 0xb6], Alu, false),
            ("msr basepri, r0", &[0x80, 0xf3, 0x11, 0x88], Alu, false),
            ("mrs r0, primask", &[0xef, 0xf3, 0x10, 0x80], Alu, false),
            ("dsb sy", &[0xbf, 0xf3, 0x4f, 0x8f], Alu, false),
            ("wfi", &[0x30, 0xbf], Alu, false),
            (
                "vldr s0, [r0]",
                &[0x90, 0xed, 0x00, 0x0a],
                FpLoadStore,
                false,
            ),
            (
                "vstr s1, [r0, #4]",
                &[0xc0, 0xed, 0x01, 0x0a],
                FpLoadStore,
                false,
            ),
            (
                "vldr d0, [r0]",
                &[0x90, 0xed, 0x00, 0x0b],
                FpLoadStore,
                false,
            ),
            (
                "vpush {s16-s19}",
                &[0x2d, 0xed, 0x04, 0x8a],
                FpMultiple(4),
                false,
            ),
            (
                "vpop {s16-s19}",
                &[0xbd, 0xec, 0x04, 0x8a],
                FpMultiple(4),
                false,
            ),
            (
                "vldmia r0!, {s0-s7}",
                &[0xb0, 0xec, 0x08, 0x0a],
                FpMultiple(8),
                false,
            ),
            (
                "vstmia r0, {d0, d1}",
                &[0x80, 0xec, 0x04, 0x0b],
                FpMultiple(4),
                false,
            ),
            ("vadd.f32", &[0x30, 0xee, 0x81, 0x0a], Fp, false),
            ("vmul.f32", &[0x20, 0xee, 0x81, 0x0a], Fp, false),
            ("vnmul.f32", &[0x20, 0xee, 0xc1, 0x0a], Fp, false),
            ("vmla.f32", &[0x00, 0xee, 0x81, 0x0a], FpMac, false),
            ("vmls.f32", &[0x00, 0xee, 0xc1, 0x0a], FpMac, false),
            ("vnmla.f32", &[0x10, 0xee, 0xc1, 0x0a], FpMac, false),
            ("vfma.f32", &[0xa0, 0xee, 0x81, 0x0a], FpMac, false),
            ("vfnms.f32", &[0x90, 0xee, 0x81, 0x0a], FpMac, false),
            ("vdiv.f32", &[0x80, 0xee, 0x81, 0x0a], FpDivSqrt, false),
            ("vsqrt.f32", &[0xb1, 0xee, 0xe0, 0x0a], FpDivSqrt, false),
            ("vabs.f32", &[0xb0, 0xee, 0xe0, 0x0a], Fp, false),
            ("vneg.f32", &[0xb1, 0xee, 0x60, 0x0a], Fp, false),
            ("vcvt.s32.f32", &[0xbd, 0xee, 0xe0, 0x0a], Fp, false),
            ("vcmp.f32", &[0xb4, 0xee, 0x60, 0x0a], Fp, false),
            ("vmov.f32 s0, #1.0", &[0xb7, 0xee, 0x00, 0x0a], Fp, false),
            ("vmov r0, s1", &[0x10, 0xee, 0x90, 0x0a], Fp, false),
            ("vmov s1, r0", &[0x00, 0xee, 0x90, 0x0a], Fp, false),
            (
                "vmrs APSR_nzcv, fpscr",
                &[0xf1, 0xee, 0x10, 0xfa],
                Fp,
                false,
            ),
            ("vmov r0, r1, d0", &[0x51, 0xec, 0x10, 0x0b], Fp, false),
        ];
        for &(asm, enc, want, pc) in cases {
            let d = class(enc);
            assert_eq!((d.class, d.writes_pc), (want, pc), "{asm}");
        }
    }

    /// PC-relative loads and the addresses they read.
    #[test]
    fn literal_pools_are_found() {
        // ldr r0, [pc, #8] at 0x0800_0102: Align(0x0800_0106, 4) + 8.
        assert_eq!(literal(0x0800_0102, 0x4802, 0), Some(0x0800_010C));
        // ldr.w r0, [pc, #-4] (0xF85F 0x0004) at 0x0800_0200.
        assert_eq!(literal(0x0800_0200, 0xF85F, 0x0004), Some(0x0800_0200));
        // ldr.w r0, [pc, #1024] (0xF8DF 0x0400) at 0x0800_0200.
        assert_eq!(literal(0x0800_0200, 0xF8DF, 0x0400), Some(0x0800_0604));
        // vldr s0, [pc, #16] (0xED9F 0x0A04) at 0x0800_0300.
        assert_eq!(literal(0x0800_0300, 0xED9F, 0x0A04), Some(0x0800_0314));
        // ldr r0, [r1]; vldr s0, [r0]: not PC-relative.
        assert_eq!(literal(0x0800_0300, 0x6808, 0), None);
        assert_eq!(literal(0x0800_0300, 0xED90, 0x0A00), None);
        let b = block(0x0800_0102, &code(&[&[0x02, 0x48], &[0x08, 0x68]]));
        assert_eq!(b.literals, vec![0x0800_010C]);
    }

    /// ITSTATE through a block: the `ittt lo` of memcpy and the instruction after its block.
    #[test]
    fn the_it_state_after_a_block() {
        // ittt lo (0xBF3E); ldrlo; str.w lo; cmp lo: the block done, ITSTATE 0.
        let body = code(&[
            &[0x3e, 0xbf],
            &[0x8d, 0x68],
            &[0x43, 0xf8, 0x04, 0x5b],
            &[0x63, 0x45],
        ]);
        let b = block(0x0802_9ff6, &body);
        assert_eq!(b.last_it, Some((0x3E, 3)));
        assert_eq!(b.it_after(0), 0);
        // Split after its first instruction: two left (lo, then the mask shifted).
        let b = block(0x0802_9ff6, &body[..4]);
        assert_eq!(b.it_after(0), it_advance(0x3E));
        assert_ne!(b.it_after(0), 0);
        // The rest of the split block, from that state: done.
        let rest = block(0x0802_9ffa, &body[4..]);
        assert_eq!(rest.last_it, None);
        assert_eq!(rest.it_after(it_advance(0x3E)), 0);
        // nop (0xBF00) is a hint, not an IT.
        assert_eq!(block(0, &[0x00, 0xbf]).last_it, None);
    }

    /// Short sequences whose cycles the TRM states.
    #[test]
    fn sequences_cost_what_the_trm_states() {
        // ldr r0, [r1]; ldr r2, [r3, #4]; str r0, [r1, #8]: 2 + 1 + 1 (pipelined), then
        // adds: 1.
        let b = block(
            0x2000_0000,
            &code(&[&[0x08, 0x68], &[0x5a, 0x68], &[0x88, 0x60], &[0x88, 0x18]]),
        );
        assert_eq!((b.instructions, b.cycles), (4, 5));
        // adds; ldr: the load not pipelined after a data-processing one: 1 + 2.
        let b = block(0x2000_0000, &code(&[&[0x88, 0x18], &[0x08, 0x68]]));
        assert_eq!(b.cycles, 3);
        // push {r4-r7, lr} 1+5; vpush {s16-s19} 1+4; vdiv 14; vmla 3; vadd 1; sdiv 12;
        // pop {r4-r7, pc} 1+5 (its refill is the taken branch's, added when it is taken).
        let b = block(
            0x2000_0000,
            &code(&[
                &[0xf0, 0xb5],
                &[0x2d, 0xed, 0x04, 0x8a],
                &[0x80, 0xee, 0x81, 0x0a],
                &[0x00, 0xee, 0x81, 0x0a],
                &[0x30, 0xee, 0x81, 0x0a],
                &[0x91, 0xfb, 0xf2, 0xf0],
                &[0xf0, 0xbd],
            ]),
        );
        assert_eq!(b.cycles, 6 + 5 + 14 + 3 + 1 + 12 + 6);
        assert!(b.fp && b.ends_in_branch);
        // ldrd 3, vldr 2, vldmia {s0-s7} 1+8.
        let b = block(
            0x2000_0000,
            &code(&[
                &[0xd2, 0xe9, 0x00, 0x01],
                &[0x90, 0xed, 0x00, 0x0a],
                &[0xb0, 0xec, 0x08, 0x0a],
            ]),
        );
        assert_eq!(b.cycles, 3 + 2 + 9);
        assert!(!b.ends_in_branch);
    }

    /// A 32-bit instruction's length follows its first halfword (A5.1).
    #[test]
    fn thumb_instruction_lengths_follow_the_first_halfword() {
        // movs r0, #1 (16-bit); bl (32-bit: 0xF000 0xF800); bx lr (16-bit).
        let code = [0x01, 0x20, 0x00, 0xF0, 0x00, 0xF8, 0x70, 0x47];
        assert_eq!(block(0, &code).instructions, 3);
        // ldr.w r0, [r1] = 0xF8D1 0x0000: one instruction of 4 bytes.
        assert_eq!(block(0, &[0xD1, 0xF8, 0x00, 0x00]).instructions, 1);
    }

    /// The lines a block spans, an instruction straddling two lines included.
    #[test]
    fn lines_follow_the_code() {
        // Eight 16-bit adds from 0x0800_000C: two in the first line, six in the next.
        let b = block(0x0800_000C, &[0x88, 0x18].repeat(8));
        assert_eq!(b.lines, vec![(0x0800_0000, 2), (0x0800_0010, 6)]);
        // A wide add at 0x0800_000E spans both lines.
        let b = block(0x0800_000E, &[0x01, 0xeb, 0x82, 0x00]);
        assert_eq!(b.lines, vec![(0x0800_0000, 1), (0x0800_0010, 0)]);
    }

    /// The accelerator at 5 wait states, everything on (as the firmware sets FLASH_ACR: 0x705).
    fn art() -> Art {
        Art::new(5 | 1 << 8 | 1 << 9 | 1 << 10)
    }

    /// A loop that fits the instruction cache stalls only on its first pass; one larger than
    /// the cache's 64 lines misses on every pass where it jumps, and runs on the prefetch
    /// where it does not.
    #[test]
    fn a_loop_in_the_cache_and_one_larger() {
        let mut a = art();
        // A 32-line loop body of 1-cycle instructions run straight, then a jump back.
        let body = block(0x0800_1000, &[0x88, 0x18].repeat(32 * 8));
        let first = a.fetch(0x0800_1000, &body, true);
        // The first line waits the wait states; each next one, prefetched, waits the fetch
        // (6 cycles) less the 8 its predecessor ran: nothing.
        assert_eq!(first, 5);
        for _ in 0..10 {
            assert_eq!(a.fetch(0x0800_1000, &body, true), 0);
        }
        // 80 lines: more than the cache holds; LRU evicts each line before it is needed
        // again, so every pass pays the jump's miss, and the prefetch covers the rest.
        let mut a = art();
        let big = block(0x0800_2000, &[0x88, 0x18].repeat(80 * 8));
        a.fetch(0x0800_2000, &big, true);
        for _ in 0..10 {
            assert_eq!(a.fetch(0x0800_2000, &big, true), 5);
        }
        // The same without the prefetch: every line of every pass waits.
        let mut a = Art::new(5 | 1 << 9 | 1 << 10);
        a.fetch(0x0800_2000, &big, true);
        assert_eq!(a.fetch(0x0800_2000, &big, true), 80 * 5);
        // Out of SRAM, or at 0 wait states: nothing.
        assert_eq!(
            art().fetch(0x2000_0000, &block(0x2000_0000, &[0; 64]), true),
            0
        );
        assert_eq!(Art::new(0x700).fetch(0x0800_2000, &big, true), 0);
    }

    /// The what-if of code fetched from SRAM: the 80-line loop that misses on every pass
    /// costs nothing inside the range given, and what it would have put in the cache stays
    /// out of it (the 32-line loop after it still hits from its second pass).
    #[test]
    fn code_taken_as_fetched_from_sram_waits_for_nothing() {
        let big = block(0x0800_2000, &[0x88, 0x18].repeat(80 * 8));
        let body = block(0x0800_1000, &[0x88, 0x18].repeat(32 * 8));
        let mut a = art();
        a.sram_code = vec![(0x0800_2000, 0x0800_2000 + 80 * 16)];
        a.fetch(0x0800_1000, &body, true);
        for _ in 0..10 {
            assert_eq!(a.fetch(0x0800_2000, &big, true), 0);
            assert_eq!(a.fetch(0x0800_1000, &body, true), 0);
        }
        // Just past the range: the flash again.
        let after = block(0x0800_2000 + 80 * 16, &[0x88, 0x18].repeat(8));
        assert_eq!(a.fetch(0x0800_2000 + 80 * 16, &after, true), 5);
    }

    /// Branch-heavy code (blocks of `adds; b` on lines of their own, each jumping to the
    /// next) against the same instructions in a straight line: every jump pays the refill
    /// and, on the first pass, the wait states of a line not yet cached.
    #[test]
    fn branch_heavy_against_straight_line() {
        let mut t = Timing::new(0x705);
        let hop = code(&[&[0x88, 0x18], &[0xfe, 0xe7]]);
        let b = block(0, &hop);
        assert_eq!((b.cycles, b.ends_in_branch), (2, true));
        let pass = |t: &mut Timing| -> u32 {
            (0..8u32)
                .map(|k| t.block(0x0800_6000 + 32 * k, &block(0x0800_6000 + 32 * k, &hop)))
                .sum()
        };
        // First pass: the first block jumped to without a branch before it (2 + 5), each
        // other one 2 + the refill + 5.
        assert_eq!(pass(&mut t), 7 + 7 * (2 + REFILL + 5));
        // Second pass, every line cached: the refills only (the first block too: the last
        // one branched to it).
        assert_eq!(pass(&mut t), 8 * (2 + REFILL));
        // The same 16 instructions' work straight: 16 adds, one line's wait.
        let mut t = Timing::new(0x705);
        let straight = block(0x0800_7000, &[0x88, 0x18].repeat(16));
        assert_eq!(t.block(0x0800_7000, &straight), 16 + 5);
    }

    /// Exception entry and return, with the lazy FP frame stacked only by a handler that runs
    /// an FP instruction over a context that had FP state.
    #[test]
    fn exceptions_and_the_lazy_fp_frame() {
        let mut t = Timing::new(0);
        let vadd = block(0x2000_0000, &[0x30, 0xee, 0x81, 0x0a]);
        let adds = block(0x2000_0000, &[0x88, 0x18]);
        // A handler without FP over an FP context: entry and return only.
        assert_eq!(t.enter(true), ENTRY);
        assert_eq!(t.block(0x2000_0000, &adds), 1);
        assert_eq!(t.exit(), RETURN);
        // With FP: the frame stacked at its first FP block, once, and unstacked at return.
        t.enter(true);
        assert_eq!(t.block(0x2000_0000, &vadd), 1 + FP_FRAME);
        assert_eq!(t.block(0x2000_0000, &vadd), 1);
        assert_eq!(t.exit(), RETURN + FP_FRAME);
        // Over a context without FP state: no frame.
        t.enter(false);
        assert_eq!(t.block(0x2000_0000, &vadd), 1);
        assert_eq!(t.exit(), RETURN);
        assert_eq!(
            t.spent.exceptions,
            3 * (ENTRY + RETURN) as u64 + 2 * FP_FRAME as u64
        );
    }

    /// Data reads of flash: a literal pool's line misses once, then hits; more than 8 lines
    /// in rotation always miss.
    #[test]
    fn literal_pools_in_the_data_cache() {
        let mut a = art();
        assert_eq!(a.read(0x0800_0100), 5);
        assert_eq!(a.read(0x0800_0104), 0);
        assert_eq!(a.read(0x0800_010C), 0);
        let mut a = art();
        let rot: Vec<u32> = (0..9).map(|k| 0x0800_0200 + 16 * k).collect();
        for &x in &rot {
            a.read(x);
        }
        for &x in &rot {
            assert_eq!(a.read(x), 5, "{x:#x}");
        }
        // SRAM reads never wait.
        assert_eq!(a.read(0x2000_0000), 0);
    }
}
