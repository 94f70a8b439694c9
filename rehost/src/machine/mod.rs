//! The emulated STM32F4: unicorn's Cortex-M4F with the memory map, the core's exception
//! model and the peripherals, its bridge, sense and encoder closed on hil-sim's plant.
//!
//! Exceptions are taken by this model, not unicorn's (its M-profile NVIC is stubbed out):
//! between runs of the engine the highest-priority pending exception whose group priority is
//! above the execution priority (the active exceptions', BASEPRI's, PRIMASK's: ARMv7-M ARM
//! B1.5.4) is entered — the basic frame, or the extended one with S0-S15 and FPSCR when
//! CONTROL.FPCA is set (B1.5.6-7), aligned to 8 bytes (xPSR bit 9), LR = EXC_RETURN. The
//! engine runs handlers as thread-mode code; their `bx lr` to EXC_RETURN fetches from
//! 0xFFFFFFxx, which is not mapped: that stop is the exception return (B1.5.8), done here.
//!
//! Time is the core's cycles at 168 MHz, by one of two models ([`TimeModel`]): a fixed number
//! of cycles per instruction (1.5, the default until the image fits its budget in cycles), or
//! the Cortex-M4's costs ([`crate::cycles`]: each instruction's class, taken branches, the
//! flash's wait states behind the ART accelerator, exception entry and return with lazy FP
//! stacking). WFI sleeps to the next event.
//!
//! By room: this module holds the board's state, its memory map and the run loop;
//! `exceptions` the core's exception model (ARMv7-M ARM B1.5); `events` the peripherals'
//! events in time and the plant; `bus` the peripheral space's reads and writes; `harness`
//! what a bench and the tests do to the board and read back.

mod bus;
mod events;
mod exceptions;
mod harness;

use bus::{periph_read, periph_write};

use std::collections::HashMap;

use hil_sim::plant::Plant;
use hil_sim::scenario::Scenario;
use unicorn_engine::unicorn_const::{Arch, HookType, MemType, Mode, Prot, uc_error};
use unicorn_engine::{RegisterARM as R, Unicorn};

use crate::core_regs::{CoreRegs, exc};
use crate::cycles::{self, Timing};
use crate::periph::{Periphs, base, tim, usart};
use crate::rtt;

/// The board an image is built for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Board {
    /// NUCLEO-F446RE (USART2 to the host).
    NucleoF446,
    /// The F405 board (USB OTG FS to the host).
    F405,
}

impl Board {
    /// Its flash size \[bytes\].
    pub fn flash_size(self) -> u32 {
        match self {
            Board::NucleoF446 => 512 * 1024,
            Board::F405 => 1024 * 1024,
        }
    }

    /// DBGMCU_IDCODE: REV_ID in 31:16, DEV_ID in 11:0 (0x421 F446 rev A, RM0390 §33.6.1;
    /// 0x413 F405 rev Z = 0x1001, RM0090 §38.6.1).
    pub fn idcode(self) -> u32 {
        match self {
            Board::NucleoF446 => 0x1000_6421,
            Board::F405 => 0x1001_6413,
        }
    }

    /// The board an image was built for, read from it: the F405's image binds the USB
    /// OTG FS interrupt to a handler of its own (its link), the Nucleo's leaves it at
    /// cortex-m-rt's `DefaultHandler`. None when the image says neither.
    pub fn of_image(elf: &[u8]) -> Option<Board> {
        use object::read::elf::ElfFile32;
        use object::{Object, ObjectSymbol};
        let file = ElfFile32::<object::Endianness>::parse(elf).ok()?;
        let addr = |name: &str| {
            file.symbols()
                .find(|s| s.name() == Ok(name))
                .map(|s| s.address())
        };
        let (otg, default) = (addr("OTG_FS")?, addr("DefaultHandler")?);
        Some(if otg != default {
            Board::F405
        } else {
            Board::NucleoF446
        })
    }

    /// Parses `nucleo-f446` or `f405`.
    pub fn parse(s: &str) -> Result<Board, String> {
        match s {
            "nucleo-f446" => Ok(Board::NucleoF446),
            "f405" => Ok(Board::F405),
            _ => Err(format!("unknown board {s:?}: nucleo-f446 or f405")),
        }
    }
}

/// How the emulated time advances.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TimeModel {
    /// This many cycles per instruction \[cycles\]; exception entry 12 (29 with the FP frame),
    /// return 10.
    Cpi(f64),
    /// The Cortex-M4's costs and the flash behind the accelerator ([`crate::cycles`]).
    Cycles,
}

impl TimeModel {
    /// `cpi` (1.5 cycles per instruction) or `cycles` (the M4's costs).
    pub fn parse(s: &str) -> Result<TimeModel, String> {
        match s {
            "cpi" => Ok(TimeModel::Cpi(1.5)),
            "cycles" => Ok(TimeModel::Cycles),
            _ => Err(format!(
                "--timing {s}: `cpi` (1.5 cycles per instruction) or `cycles` (the M4's costs)"
            )),
        }
    }
}

/// How to run.
#[derive(Debug, Clone)]
pub struct Options {
    /// The time model (the Cortex-M4's costs by default).
    pub timing: TimeModel,
    /// The plant's scenario (hil-sim's defaults when `None`).
    pub scenario: Option<Scenario>,
    /// Print log lines as they come.
    pub echo_log: bool,
    /// Serve ARM semihosting (`BKPT 0xAB`: writes to the console, the exit) as a debugger
    /// would, for a bare-metal program such as `cargo target-bench`'s
    /// ([`Machine::run_semihosted`]); without it the breakpoint is a fault.
    pub semihosting: bool,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            timing: TimeModel::Cycles,
            scenario: None,
            echo_log: false,
            semihosting: false,
        }
    }
}

/// The core clock \[Hz\].
pub const HZ: u64 = 168_000_000;
const FLASH: u64 = 0x0800_0000;
const SRAM: u64 = 0x2000_0000;
const SRAM_LEN: u64 = 128 * 1024;
/// SRAM1, the part of the SRAM SYSCFG_MEMRMP's MEM_MODE = 11 maps at 0 (RM0090 §9.2.1,
/// RM0390 §8.2.1: "SRAM1 (112 KB) mapped at 0x0000 0000"), fetched there through the I-bus.
const SRAM1_LEN: u64 = 112 * 1024;
/// SYSCFG_MEMRMP (RM0090 §9.2.1).
const SYSCFG_MEMRMP: u32 = 0x4001_3800;
const CCM: u64 = 0x1000_0000;
const SYSMEM: u64 = 0x1FFF_0000;

/// One exception handled: which, and what it cost.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Handled {
    /// Its exception number (16 + IRQ).
    pub exc: u32,
    /// Instructions it executed itself (not counting those it was preempted by).
    pub instructions: u64,
    /// Its own cycles, its entry and return included \[cycles\].
    pub cycles: u64,
    /// When it was entered \[cycles\].
    pub at: u64,
}

/// Why the run stopped short.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Stop {
    /// An exception that cannot be taken at the current priority (lockup), or the engine's
    /// error.
    Lockup(String),
}

/// One active exception.
#[derive(Debug, Clone, Copy)]
struct Active {
    exc: u32,
    instructions: u64,
    cycles: u64,
    at: u64,
}

/// Faults a test puts on the board: what the sense chain, the encoder and the supply do.
#[derive(Debug, Clone, Default)]
pub struct Inject {
    /// Every ADC conversion reads this code (a dead sense chain: its amplifier unpowered
    /// reads 0, a broken ground full scale).
    pub sense_code: Option<u32>,
    /// The next ADC conversion alone reads this code (a spike), then the plant again.
    pub sense_code_once: Option<u32>,
    /// The encoder's counter no longer follows the axis (a broken encoder cable).
    pub encoder_frozen: bool,
    /// Flash writes so far (each program store and each sector erase).
    pub flash_writes: u64,
    /// The supply fails during this flash write (counted as `flash_writes`): a program store
    /// lands on its low half-word only, an erase on the sector's first half; then nothing
    /// runs until [`Machine::power_cycle`].
    pub cut_at_flash_write: Option<u64>,
    /// The supply has failed: the core is stopped, time passes.
    pub power_lost: bool,
    /// Code patched in by [`Machine::hang_handler`], put back at the next reset: (address,
    /// the original halfword).
    patches: Vec<(u64, [u8; 2])>,
    /// [`Machine::start_late`]: the exception, how late each of its entries comes \[cycles\],
    /// and the entries left to delay.
    late_entry: Option<(u32, u64, u32)>,
}

impl Inject {
    /// Counts a flash write; true when the supply fails on it.
    fn flash_write_cut(&mut self) -> bool {
        self.flash_writes += 1;
        if self.cut_at_flash_write == Some(self.flash_writes) {
            self.power_lost = true;
            return true;
        }
        false
    }
}

/// A condition's runs of blocks (a mask held): where the current one began.
#[derive(Debug, Default, Clone, Copy)]
struct Hold {
    /// Since this time \[cycles\], from this address; `None` when not held.
    since: Option<(u64, u64)>,
}

impl Hold {
    /// The condition at a block starting at `addr` at time `now` \[cycles\]: when a run ends
    /// here, its length \[cycles\] and where it began.
    fn update(&mut self, held: bool, now: u64, addr: u64) -> Option<(u64, u64)> {
        match (held, self.since) {
            (true, None) => {
                self.since = Some((now, addr));
                None
            }
            (false, Some((from, at))) => {
                self.since = None;
                Some((now - from, at))
            }
            _ => None,
        }
    }
}

/// The state the engine's hooks reach.
/// What a semihosted program wrote and how it ended.
#[derive(Debug, Clone, Default)]
pub struct Semihost {
    /// The console's bytes.
    pub out: Vec<u8>,
    /// Its exit: success (ADP_Stopped_ApplicationExit) or not; none while it runs.
    pub exited: Option<bool>,
}

pub struct Chip {
    /// The core's registers.
    pub core: CoreRegs,
    /// The peripherals.
    pub p: Periphs,
    /// Time \[cycles\].
    pub cycles: u64,
    /// Instructions executed.
    pub instructions: u64,
    cycle_frac: f64,
    /// The time model.
    pub model: TimeModel,
    /// The M4's costs and the accelerator (with [`TimeModel::Cycles`]).
    pub timing: Timing,
    /// FLASH_ACR as the accelerator was last configured from.
    acr_seen: u32,
    /// Stop the engine at or after this time \[cycles\].
    next_stop: u64,
    /// The blocks seen, decoded and costed (by address and size).
    blocks: rustc_hash::FxHashMap<(u64, u32), std::sync::Arc<cycles::Block>>,
    /// Where the last block run ended, and ITSTATE after it (A7.3.3).
    prev_end: u64,
    it_next: u8,
    /// The run was stopped before a block, in this ITSTATE: the engine's own may be stale
    /// (it keeps what it last stored, before the last load or store of an IT block:
    /// unicorn-engine issue 2309), so it is written back before the run goes on.
    it_fix: Option<u8>,
    /// The run stopped at a WFE or WFI: the core sleeps there unless the event register is
    /// set (WFE) or an interrupt wakes it.
    pub slept: bool,
    /// The event register (B1.5.18): set by exception entry and return and by SEV.
    event: bool,
    /// The encoder's count from the plant, and TIM2's offset to it.
    enc_counts: i64,
    enc_offset: u32,
    /// The active exceptions, innermost last.
    active: Vec<Active>,
    /// Instructions in thread mode.
    pub thread_instructions: u64,
    /// Cycles in thread mode, sleep excluded \[cycles\].
    pub thread_cycles: u64,
    /// The lowest SP seen, and where (the exceptions active then).
    pub sp_min: u32,
    /// The exceptions active at the lowest SP.
    pub sp_min_context: Vec<u32>,
    /// The stack guard's range, once the MPU is on.
    guard: Option<(u32, u32)>,
    /// The SP that entered the guard.
    pub guard_hit: Option<u32>,
    /// Code fetched at 0 without SRAM1 remapped there (where the chip shows the flash, which
    /// the model does not): the address.
    pub fetch_unremapped: Option<u32>,
    /// PRIMASK's holds.
    primask: Hold,
    /// The longest time PRIMASK was held \[cycles\].
    pub primask_max: u64,
    /// Where the longest hold began (the first block run with PRIMASK set).
    pub primask_max_at: u64,
    /// The exception whose hold-off by a mask is measured (the control interrupt), if any:
    /// [`Chip::held_max`]. Cleared at a reset.
    pub watch: Option<u32>,
    /// Instructions the watched exception ran from flash, by block address (its code belongs
    /// in SRAM: `firmware/build.rs`'s `.ramcode`).
    pub watch_flash: rustc_hash::FxHashMap<u32, u64>,
    /// The watched exception's holds.
    held: Hold,
    /// The watched exception's own blocks' cycles by what they went to (under
    /// [`TimeModel::Cycles`]; its entries and returns are in [`Handled::cycles`]).
    pub watch_spent: cycles::Spent,
    /// The longest time \[cycles\] the watched exception was held off by PRIMASK or
    /// BASEPRI in a context it would otherwise preempt (thread mode, or a handler below it):
    /// the delay a critical section adds to its start.
    pub held_max: u64,
    /// Where that longest hold began.
    pub held_max_at: u64,
    /// An interrupt is pending and masked, by these PRIMASK and BASEPRI values: the run stops
    /// at the first block where they differ, to take it there.
    masked_pending: Option<(u32, u32)>,
    /// A write to flash outside a programming sequence (address).
    pub bad_flash_write: Option<u32>,
    /// Faults put on the board by a test ([`Inject`]).
    pub inject: Inject,
    /// CPU reads of USART2's DR while its DMA receives (CR3.DMAR): each could take a byte
    /// that arrived in the instant before the DMA served it (RM0390 §25.6.1: a DR read
    /// clears RXNE), and is counted.
    pub dr_reads_under_dma: u64,
    /// Instructions and cycles by block address, while profiling.
    profile: Option<HashMap<u64, (u64, u64)>>,
    /// Profile only this exception's own instructions (all when `None`).
    profile_exc: Option<u32>,
    /// With `profile_exc`: only its runs of more than this many cycles.
    profile_over: u64,
    /// The blocks of the profiled exception's run in progress: address, instructions, cycles.
    run_blocks: Vec<(u64, u32, u64)>,
    /// Semihosting's console and exit, when served.
    pub semihost: Option<Semihost>,
}

impl Chip {
    fn now(&self) -> u64 {
        self.cycles
    }

    /// `b`, at `addr`, about to run: its instructions and cycles counted; its cycles.
    fn run_block(&mut self, addr: u32, b: &cycles::Block) -> u64 {
        let cycles = match self.model {
            TimeModel::Cpi(cpi) => self.cpi_cycles(b.instructions, cpi),
            TimeModel::Cycles => {
                let acr = self.p.flash.acr();
                if acr != self.acr_seen {
                    self.timing.art.configure(acr);
                    self.acr_seen = acr;
                }
                let s = self.timing.block_spent(addr, b);
                if self.watch.is_some() && self.active.last().map(|a| a.exc) == self.watch {
                    self.watch_spent.add(&s);
                }
                s.total()
            }
        };
        self.count(b.instructions, cycles);
        cycles
    }

    /// `n` one-cycle instructions run outside a block (a WFE or WFI completing).
    fn add_instructions(&mut self, n: u32) {
        let cycles = match self.model {
            TimeModel::Cpi(cpi) => self.cpi_cycles(n, cpi),
            TimeModel::Cycles => n as u64,
        };
        self.count(n, cycles);
    }

    /// `n` instructions at `cpi` cycles each, the fraction carried \[cycles\].
    fn cpi_cycles(&mut self, n: u32, cpi: f64) -> u64 {
        let c = n as f64 * cpi + self.cycle_frac;
        let whole = c.floor();
        self.cycle_frac = c - whole;
        whole as u64
    }

    /// `n` instructions and their `cycles` counted to what runs now.
    fn count(&mut self, n: u32, cycles: u64) {
        self.instructions += n as u64;
        match self.active.last_mut() {
            Some(a) => a.instructions += n as u64,
            None => self.thread_instructions += n as u64,
        }
        self.add_cycles(cycles);
    }

    /// `n` cycles spent by what runs now (an exception, or thread mode).
    fn add_cycles(&mut self, n: u64) {
        self.cycles += n;
        match self.active.last_mut() {
            Some(a) => a.cycles += n,
            None => self.thread_cycles += n,
        }
    }

    fn stop_soon(&mut self) {
        self.next_stop = 0;
    }
}

/// The emulated board.
pub struct Machine {
    uc: Unicorn<'static, Chip>,
    /// The SRAM's bytes, mapped at 0x2000_0000 and (SRAM1) again at 0: the engine reads and
    /// writes them through both (dropped after `uc`, declared before it).
    _sram: Box<[u8]>,
    board: Board,
    image: Vec<u8>,
    /// (address, bytes) of the image's loadable segments.
    segments: Vec<(u64, Vec<u8>)>,
    vector_table: u32,
    rtt_cb: Option<u32>,
    log: Option<rtt::Log>,
    echo_log: bool,
    /// The plant.
    pub plant: Plant,
    /// The lowest and highest codes the sense amplifier's output reaches on this ADC
    /// (`[plant.sense] swing_v`).
    sense_limits: (f64, f64),
    /// When the plant's state is \[cycles\].
    plant_at: u64,
    /// The bridge's duty since the last update event \[−1, 1\] (the compare values active then).
    applied_duty: f64,
    /// Every exception handled, in order.
    pub handled: Vec<Handled>,
    /// Resets so far (watchdog or software).
    pub resets: u32,
    /// Log lines so far.
    pub log_lines: Vec<rtt::Line>,
    /// The watchdog's resets so far: when, and where the image was.
    pub watchdog_resets: Vec<String>,
    /// The faults raised so far (time, kind, address, why).
    pub faults: Vec<String>,
}

/// ITSTATE from a PSR's IT bits (IT[1:0] at 26:25, IT[7:2] at 15:10: ARMv7-M ARM B1.4.2).
fn it_of(psr: u32) -> u8 {
    (((psr >> 25) & 3) | ((psr >> 8) & 0xFC)) as u8
}

/// `psr` with its IT bits set to `it`.
fn with_it(psr: u32, it: u8) -> u32 {
    let it = it as u32;
    (psr & !(3 << 25) & !(0x3F << 10)) | ((it & 3) << 25) | ((it >> 2) << 10)
}

fn err(e: uc_error) -> String {
    format!("unicorn: {e:?}")
}

impl Machine {
    /// Loads `elf` for `board`: its segments into flash and RAM, the plant, reset.
    pub fn new(elf: &[u8], board: Board, opts: Options) -> Result<Machine, String> {
        use object::read::elf::{ElfFile32, ProgramHeader};
        use object::{Object, ObjectSymbol};
        let file =
            ElfFile32::<object::Endianness>::parse(elf).map_err(|e| format!("the image: {e}"))?;
        let endian = file.endian();
        // The loadable segments at their physical (load) addresses: .data's initial values
        // sit in flash, where the startup code copies them from.
        let mut segments = Vec::new();
        for ph in file.elf_program_headers() {
            if ph.p_type(endian) != object::elf::PT_LOAD {
                continue;
            }
            let data = ph
                .data(endian, elf)
                .map_err(|()| "the image: a segment outside the file".to_string())?;
            if !data.is_empty() {
                segments.push((ph.p_paddr(endian) as u64, data.to_vec()));
            }
        }
        let rtt_cb = file
            .symbols()
            .find(|s| s.name() == Ok("_SEGGER_RTT"))
            .map(|s| s.address() as u32);
        let vector_table = FLASH as u32;
        let log = rtt::Log::new(elf)?;
        let scenario = match opts.scenario {
            Some(s) => s,
            None => Scenario::parse("", "defaults").map_err(|e| e.to_string())?,
        };
        let plant = Plant::new(&scenario.plant, scenario.plant.seed).map_err(|e| e.to_string())?;

        let chip = Chip {
            core: CoreRegs::new(board.idcode()),
            p: Periphs::new(board.flash_size(), HZ),
            cycles: 0,
            instructions: 0,
            cycle_frac: 0.0,
            model: opts.timing,
            timing: Timing::new(0),
            acr_seen: 0,
            next_stop: u64::MAX,
            blocks: rustc_hash::FxHashMap::default(),
            prev_end: 0,
            it_next: 0,
            it_fix: None,
            enc_counts: plant.encoder(),
            enc_offset: 0,
            active: Vec::new(),
            thread_instructions: 0,
            thread_cycles: 0,
            sp_min: u32::MAX,
            sp_min_context: Vec::new(),
            guard: None,
            guard_hit: None,
            fetch_unremapped: None,
            primask: Hold::default(),
            primask_max: 0,
            primask_max_at: 0,
            watch: None,
            watch_flash: rustc_hash::FxHashMap::default(),
            held: Hold::default(),
            held_max: 0,
            watch_spent: cycles::Spent::default(),
            held_max_at: 0,
            masked_pending: None,
            bad_flash_write: None,
            inject: Inject::default(),
            dr_reads_under_dma: 0,
            slept: false,
            event: false,
            profile: None,
            profile_exc: None,
            profile_over: 0,
            run_blocks: Vec::new(),
            semihost: opts.semihosting.then(Semihost::default),
        };
        let mut uc =
            Unicorn::new_with_data(Arch::ARM, Mode::THUMB | Mode::MCLASS, chip).map_err(err)?;
        uc.ctl_set_cpu_model(unicorn_engine::ArmCpuModel::CORTEX_M4 as i32)
            .map_err(err)?;
        uc.mem_map(FLASH, board.flash_size() as u64, Prot::READ | Prot::EXEC)
            .map_err(err)?;
        // The SRAM at its address and SRAM1 again at 0, one memory: the image that remaps
        // SRAM1 at 0 (SYSCFG_MEMRMP) runs code it copied there through the alias. A fetch at
        // 0 without the remap is a fault (the hook below): there the chip shows the flash.
        let mut sram = vec![0u8; SRAM_LEN as usize].into_boxed_slice();
        // SAFETY: the buffer lives as long as the engine (the machine owns both, and drops
        // the engine first); both mappings are within it.
        unsafe {
            let ptr = sram.as_mut_ptr().cast::<core::ffi::c_void>();
            uc.mem_map_ptr(SRAM, SRAM_LEN, Prot::ALL, ptr)
                .map_err(err)?;
            uc.mem_map_ptr(0, SRAM1_LEN, Prot::ALL, ptr).map_err(err)?;
        }
        if board == Board::F405 {
            uc.mem_map(CCM, 64 * 1024, Prot::READ | Prot::WRITE)
                .map_err(err)?;
            // Its link is USB: a host at the other end of the cable from power-up.
            uc.get_data_mut().p.usb_host.plug(0);
        }
        // System memory and OTP: the unique ID (0x1FFF7A10) and the flash size (0x1FFF7A22).
        uc.mem_map(SYSMEM, 0x1_0000, Prot::READ).map_err(err)?;
        let mut sys = vec![0u8; 0x1_0000];
        sys[0x7A10..0x7A1C].copy_from_slice(b"GMS-REHOST-1");
        let kib = (board.flash_size() / 1024) as u16;
        sys[0x7A22..0x7A24].copy_from_slice(&kib.to_le_bytes());
        uc.mem_write(SYSMEM, &sys).map_err(err)?;
        // Flash erased.
        uc.mem_write(FLASH, &vec![0xFF; board.flash_size() as usize])
            .map_err(err)?;

        uc.mmio_map(
            0x4000_0000,
            0x8_0000,
            Some(|uc: &mut Unicorn<'_, Chip>, off: u64, size: usize| {
                periph_read(uc, 0x4000_0000 + off as u32, size) as u64
            }),
            Some(
                |uc: &mut Unicorn<'_, Chip>, off: u64, size: usize, v: u64| {
                    periph_write(uc, 0x4000_0000 + off as u32, size, v as u32)
                },
            ),
        )
        .map_err(err)?;
        // USB OTG FS (the F405's link): its register model (`periph::otg`), word-wide as the
        // driver accesses it; a narrower write merges into the value without a read's side
        // effects (GRXSTSP's pop, the FIFO's).
        uc.mmio_map(
            u64::from(base::OTG_FS),
            0x4_0000,
            Some(|uc: &mut Unicorn<'_, Chip>, off: u64, size: usize| {
                let c = uc.get_data_mut();
                let off = off as u32;
                let v = if size == 4 {
                    c.p.otg.read(off & !3)
                } else {
                    c.p.otg.peek(off & !3)
                };
                let v = v >> ((off & 3) * 8);
                u64::from(match size {
                    1 => v & 0xFF,
                    2 => v & 0xFFFF,
                    _ => v,
                })
            }),
            Some(
                |uc: &mut Unicorn<'_, Chip>, off: u64, size: usize, v: u64| {
                    let c = uc.get_data_mut();
                    let off = off as u32;
                    let word = off & !3;
                    let v = if size < 4 {
                        let shift = (off & 3) * 8;
                        let mask = if size == 1 { 0xFF } else { 0xFFFF } << shift;
                        (c.p.otg.peek(word) & !mask) | (((v as u32) << shift) & mask)
                    } else {
                        v as u32
                    };
                    c.p.otg.write(word, v);
                    // The line and the host's next transaction looked at again.
                    c.stop_soon();
                },
            ),
        )
        .map_err(err)?;
        uc.mmio_map(
            0xE000_0000,
            0x10_0000,
            Some(|uc: &mut Unicorn<'_, Chip>, off: u64, _size: usize| {
                let c = uc.get_data();
                c.core.read(0xE000_0000 + off as u32, c.now()) as u64
            }),
            Some(
                |uc: &mut Unicorn<'_, Chip>, off: u64, size: usize, v: u64| {
                    let addr = 0xE000_0000 + off as u32;
                    let c = uc.get_data_mut();
                    let now = c.now();
                    c.core.write(addr, size, v as u32, now);
                    if (0xE000_ED94..=0xE000_EDB8).contains(&addr) {
                        c.guard = c.core.mpu_guards().next();
                    }
                    if (0xE000_E100..0xE000_E500).contains(&addr)
                        || addr == 0xE000_ED04
                        || addr == 0xE000_ED0C
                        || addr == 0xE000_EF00
                    {
                        c.stop_soon();
                    }
                },
            ),
        )
        .map_err(err)?;

        // Flash written outside programming: PGSERR (the store still lands, as unicorn's
        // hook lets it; the firmware's driver never does it).
        uc.add_mem_hook(
            HookType::MEM_WRITE_PROT,
            FLASH,
            FLASH + board.flash_size() as u64 - 1,
            |uc: &mut Unicorn<'_, Chip>, _t: MemType, addr: u64, size: usize, v: i64| {
                let c = uc.get_data_mut();
                if !c.p.flash.programming() {
                    c.p.flash.bad_write();
                    c.bad_flash_write.get_or_insert(addr as u32);
                    return true;
                }
                // Programming clears bits only (RM0090 §3.6.4: a 1 cannot be written over a
                // 0 without an erase).
                let mut old = vec![0u8; size];
                let _ = uc.mem_read(addr, &mut old);
                // The supply failing mid-store: only the low half of it lands (and nothing
                // after it, in what is left of the block).
                let c = uc.get_data_mut();
                if c.inject.power_lost {
                    return true;
                }
                let cut = c.inject.flash_write_cut();
                if cut {
                    c.stop_soon();
                }
                let landing = if cut { size.div_ceil(2) } else { size };
                let new: Vec<u8> = old
                    .iter()
                    .zip((v as u64).to_le_bytes())
                    .enumerate()
                    .map(|(k, (o, n))| if k < landing { o & n } else { *o })
                    .collect();
                let _ = uc.mem_write(addr, &new);
                true
            },
        )
        .map_err(err)?;

        // Every block: its instructions counted (when it runs: a stop requested here ends the
        // run before the block), the stack's depth, PRIMASK's hold, the guard.
        uc.add_block_hook(1, 0, |uc: &mut Unicorn<'_, Chip>, addr: u64, size: u32| {
            let b = match uc.get_data().blocks.get(&(addr, size)) {
                Some(b) => b.clone(),
                None => {
                    let mut code = vec![0u8; size as usize];
                    let b = if uc.mem_read(addr, &mut code).is_ok() {
                        cycles::block(addr as u32, &code)
                    } else {
                        cycles::Block {
                            bytes: size,
                            instructions: 1,
                            cycles: 1,
                            ..Default::default()
                        }
                    };
                    let b = std::sync::Arc::new(b);
                    uc.get_data_mut().blocks.insert((addr, size), b.clone());
                    b
                }
            };
            let n = b.instructions;
            let sp = uc.reg_read(R::SP).unwrap_or(0) as u32;
            let primask = uc.reg_read(R::PRIMASK).unwrap_or(0) & 1 != 0;
            let basepri = uc.reg_read(R::BASEPRI).unwrap_or(0) as u32 & 0xFF;
            // An interrupt held pending by a mask: the run stops where the mask changes.
            let unmasked = uc
                .get_data()
                .masked_pending
                .is_some_and(|m| m != (primask as u32, basepri));
            let c = uc.get_data_mut();
            if let Some(w) = c.watch {
                // Held off by a mask alone: enabled, the active exceptions would let it in
                // (B1.5.4), PRIMASK or BASEPRI (a non-zero one at or above its priority) does
                // not.
                let enabled = w < exc::IRQ0 || c.core.enabled[(w - exc::IRQ0) as usize];
                let p = c.core.group_priority(w);
                let held = enabled
                    && p < c.active_priority()
                    && (primask || (basepri != 0 && basepri as i32 <= p));
                if let Some((n, at)) = c.held.update(held, c.cycles, addr)
                    && n > c.held_max
                {
                    (c.held_max, c.held_max_at) = (n, at);
                }
            }
            if c.watch.is_some()
                && (FLASH..FLASH + 0x10_0000).contains(&addr)
                && c.active.last().map(|a| a.exc) == c.watch
            {
                *c.watch_flash.entry(addr as u32).or_default() += u64::from(n);
            }
            if sp < c.sp_min {
                c.sp_min = sp;
                c.sp_min_context = c.active.iter().map(|a| a.exc).collect();
            }
            if let Some((n, at)) = c.primask.update(primask, c.cycles, addr)
                && n > c.primask_max
            {
                (c.primask_max, c.primask_max_at) = (n, at);
            }
            let mut stop = c.cycles >= c.next_stop || unmasked;
            if addr < SRAM1_LEN
                && c.p.plain.get(&SYSCFG_MEMRMP).is_none_or(|m| m & 3 != 3)
                && c.fetch_unremapped.is_none()
            {
                c.fetch_unremapped = Some(addr as u32);
                stop = true;
            }
            if let Some((g, len)) = c.guard
                && sp >= g
                && sp < g + len
                && c.guard_hit.is_none()
            {
                c.guard_hit = Some(sp);
                stop = true;
            }
            // ITSTATE where this block begins: the one after the block before when it runs on
            // from it (an IT block split by a page boundary), else none (a branch ends one).
            let it = if addr == c.prev_end { c.it_next } else { 0 };
            if stop {
                c.it_fix = Some(it);
                let _ = uc.emu_stop();
            } else {
                c.prev_end = addr + size as u64;
                c.it_next = b.it_after(it);
                let cycles = c.run_block(addr as u32, &b);
                let here = c.active.last().map(|a| a.exc);
                if c.profile.is_some() {
                    if c.profile_exc.is_none() {
                        if let Some(p) = c.profile.as_mut() {
                            let e = p.entry(addr).or_insert((0, 0));
                            (e.0, e.1) = (e.0 + n as u64, e.1 + cycles);
                        }
                    } else if c.profile_exc == here {
                        c.run_blocks.push((addr, n, cycles));
                    }
                }
            }
        })
        .map_err(err)?;
        // WFE and WFI (the engine runs WFE as a no-op and WFI as a stop): a hook on each, the
        // core sleeps there (`step_once`).
        for (addr, data) in &segments {
            if *addr < FLASH || *addr >= FLASH + board.flash_size() as u64 {
                continue;
            }
            for k in (0..data.len().saturating_sub(1)).step_by(2) {
                let hw = u16::from_le_bytes([data[k], data[k + 1]]);
                if hw == 0xBF20 || hw == 0xBF30 {
                    let at = addr + k as u64;
                    uc.add_code_hook(at, at, |uc: &mut Unicorn<'_, Chip>, _a: u64, _s: u32| {
                        uc.get_data_mut().slept = true;
                        let _ = uc.emu_stop();
                    })
                    .map_err(err)?;
                }
            }
        }

        let mut m = Machine {
            uc,
            _sram: sram,
            board,
            image: elf.to_vec(),
            segments,
            vector_table,
            rtt_cb,
            log,
            echo_log: opts.echo_log,
            sense_limits: scenario.plant.sense.code_limits(3.3, 4095.0),
            plant,
            plant_at: 0,
            applied_duty: 0.0,
            handled: Vec::new(),
            resets: 0,
            log_lines: Vec::new(),
            watchdog_resets: Vec::new(),
            faults: Vec::new(),
        };
        m.load()?;
        m.reset_core()?;
        Ok(m)
    }

    /// The board.
    pub fn board(&self) -> Board {
        self.board
    }

    /// The image's bytes.
    pub fn image(&self) -> &[u8] {
        &self.image
    }

    /// The program counter now.
    pub fn pc(&self) -> u32 {
        self.reg(R::PC)
    }

    /// The exceptions active now, outermost first.
    pub fn active_exceptions(&self) -> Vec<u32> {
        self.chip().active.iter().map(|a| a.exc).collect()
    }

    /// The chip's state.
    pub fn chip(&self) -> &Chip {
        self.uc.get_data()
    }

    /// The chip's state, to change (faults, the line).
    pub fn chip_mut(&mut self) -> &mut Chip {
        self.uc.get_data_mut()
    }

    /// Time \[s\].
    pub fn seconds(&self) -> f64 {
        self.chip().cycles as f64 / HZ as f64
    }

    fn load(&mut self) -> Result<(), String> {
        for (addr, data) in &self.segments {
            self.uc.mem_write(*addr, data).map_err(err)?;
        }
        Ok(())
    }

    /// The semihosting breakpoint (`BKPT 0xAB`, 0xBEAB) the engine stopped at: at `pc`, or
    /// just before it.
    fn semihost_at(&self, pc: u32) -> Option<u32> {
        let half = |a: u32| {
            let mut b = [0u8; 2];
            self.uc.mem_read(u64::from(a), &mut b).ok()?;
            Some(u16::from_le_bytes(b))
        };
        [pc, pc.wrapping_sub(2)]
            .into_iter()
            .find(|&a| half(a) == Some(0xBEAB))
    }

    /// One semihosting call (ARM's "Semihosting for AArch32 and AArch64", the operation in
    /// r0, its argument or argument block at r1, the result in r0): SYS_OPEN (":tt" only),
    /// SYS_CLOSE, SYS_WRITEC, SYS_WRITE0, SYS_WRITE to the console, SYS_EXIT and
    /// SYS_EXIT_EXTENDED; anything else returns −1. The program goes on after the breakpoint.
    fn semihost_call(&mut self, pc: u32) -> Result<(), String> {
        let at = self.semihost_at(pc).ok_or("no semihosting breakpoint")?;
        let (op, arg) = (self.reg(R::R0), self.reg(R::R1));
        let word = |m: &Machine, i: u32| m.read_u32(arg.wrapping_add(4 * i));
        let mut out = Vec::new();
        let mut exit = None;
        let ret: u32 = match op {
            0x01 => 1,
            0x02 => 0,
            0x03 => {
                let mut b = [0u8; 1];
                self.uc.mem_read(u64::from(arg), &mut b).map_err(err)?;
                out.push(b[0]);
                0
            }
            0x04 => {
                let mut a = arg;
                loop {
                    let mut b = [0u8; 1];
                    self.uc.mem_read(u64::from(a), &mut b).map_err(err)?;
                    if b[0] == 0 || out.len() > 1 << 16 {
                        break;
                    }
                    out.push(b[0]);
                    a += 1;
                }
                0
            }
            0x05 => {
                let (ptr, len) = (word(self, 1)?, word(self, 2)?);
                let mut b = vec![0u8; len.min(1 << 16) as usize];
                self.uc.mem_read(u64::from(ptr), &mut b).map_err(err)?;
                out.extend_from_slice(&b);
                0
            }
            0x18 => {
                exit = Some(arg == 0x2_0026);
                0
            }
            0x20 => {
                exit = Some(word(self, 0)? == 0x2_0026 && word(self, 1)? == 0);
                0
            }
            _ => u32::MAX,
        };
        self.uc.reg_write(R::R0, u64::from(ret)).map_err(err)?;
        self.uc.reg_write(R::PC, u64::from(at + 2)).map_err(err)?;
        let c = self.chip_mut();
        c.add_instructions(1);
        if let Some(sh) = c.semihost.as_mut() {
            sh.out.extend(out);
            if exit.is_some() {
                sh.exited = exit;
            }
        }
        Ok(())
    }

    /// Runs a semihosted program until it exits, at most `seconds` of device time: whether it
    /// exited with success, and what it wrote.
    pub fn run_semihosted(&mut self, seconds: f64) -> Result<(bool, String), String> {
        let until = self.chip().cycles + (seconds * HZ as f64) as u64;
        let text = |m: &Machine| {
            String::from_utf8_lossy(m.chip().semihost.as_ref().map_or(&[][..], |s| &s.out))
                .to_string()
        };
        loop {
            if let Some(ok) = self.chip().semihost.as_ref().and_then(|s| s.exited) {
                return Ok((ok, text(self)));
            }
            if self.chip().cycles >= until {
                return Err(format!(
                    "no exit within {seconds} s of device time: {}",
                    text(self)
                ));
            }
            let slice = (self.chip().cycles + HZ / 100).min(until);
            if let Err(e) = self.run_until(slice) {
                return Err(format!("{e:?}: {}", text(self)));
            }
        }
    }

    fn read_u32(&self, addr: u32) -> Result<u32, String> {
        let mut b = [0u8; 4];
        self.uc.mem_read(addr as u64, &mut b).map_err(err)?;
        Ok(u32::from_le_bytes(b))
    }

    fn write_u32(&mut self, addr: u32, v: u32) -> Result<(), String> {
        self.uc
            .mem_write(addr as u64, &v.to_le_bytes())
            .map_err(err)
    }

    /// The core from reset: SP and PC from the vector table, CONTROL, PRIMASK, BASEPRI 0.
    fn reset_core(&mut self) -> Result<(), String> {
        let sp = self.read_u32(self.vector_table)?;
        let pc = self.read_u32(self.vector_table + 4)?;
        for r in [
            R::R0,
            R::R1,
            R::R2,
            R::R3,
            R::R4,
            R::R5,
            R::R6,
            R::R7,
            R::R8,
            R::R9,
            R::R10,
            R::R11,
            R::R12,
        ] {
            self.uc.reg_write(r, 0).map_err(err)?;
        }
        self.uc.reg_write(R::PRIMASK, 0).map_err(err)?;
        self.uc.reg_write(R::BASEPRI, 0).map_err(err)?;
        self.uc.reg_write(R::CONTROL, 0).map_err(err)?;
        self.uc.reg_write(R::MSP, sp as u64).map_err(err)?;
        self.uc.reg_write(R::SP, sp as u64).map_err(err)?;
        self.uc.reg_write(R::LR, 0xFFFF_FFFF).map_err(err)?;
        self.uc.reg_write(R::PC, (pc & !1) as u64).map_err(err)?;
        let c = self.uc.get_data_mut();
        c.active.clear();
        c.timing.reset();
        (c.prev_end, c.it_next, c.it_fix) = (0, 0, None);
        c.acr_seen = 0;
        c.guard = None;
        c.primask = Hold::default();
        // The watch is armed once the image's loop runs (its interrupt at its priority); a
        // reset ends it (the start-up's drivers run that interrupt's line at theirs).
        c.held = Hold::default();
        c.watch = None;
        Ok(())
    }

    /// A system reset of cause `rcc_flag` (RCC_CSR): the peripherals and the core back to
    /// reset, RAM and flash kept, the image started again.
    fn system_reset(&mut self, rcc_flag: u32) -> Result<(), String> {
        // A hang patched in was the running image's, not its flash's.
        for (addr, orig) in std::mem::take(&mut self.chip_mut().inject.patches) {
            self.uc.mem_write(addr, &orig).map_err(err)?;
            self.uc.ctl_remove_cache(addr, addr + 2).map_err(err)?;
        }
        let c = self.uc.get_data_mut();
        let mut rcc = c.p.rcc.clone();
        rcc.reset(rcc_flag);
        let size = self.board.flash_size();
        let options = c.p.flash.options();
        let host = std::mem::take(&mut c.p.usb_host);
        c.p = Periphs::new(size, HZ);
        c.p.rcc = rcc;
        c.p.usb_host = host;
        c.p.flash.restore_options(options);
        c.core = CoreRegs::new(self.board.idcode());
        // MEMRMP back to its boot value (the plain registers are new): the code translated at
        // the alias is dropped, the next copy is run afresh.
        self.uc.ctl_remove_cache(0, SRAM1_LEN).map_err(err)?;
        self.resets += 1;
        self.reset_core()
    }

    fn reg(&self, r: R) -> u32 {
        self.uc.reg_read(r).unwrap_or(0) as u32
    }

    /// The engine's ITSTATE (A7.3.3): its CPSR's IT bits; its xPSR reads them as zero, as
    /// MRS does.
    fn it_state(&self) -> u8 {
        it_of(self.reg(R::CPSR))
    }

    /// Sets the engine's ITSTATE, nothing else of its CPSR.
    fn set_it_state(&mut self, it: u8) -> Result<(), String> {
        let c = with_it(self.reg(R::CPSR), it);
        self.uc.reg_write(R::CPSR, c as u64).map_err(err)
    }

    /// Runs until `until` \[cycles\] or a lockup.
    pub fn run_until(&mut self, until: u64) -> Result<(), Stop> {
        while self.chip().cycles < until {
            if self.chip().inject.power_lost {
                // No supply: nothing runs, time passes.
                let c = self.chip_mut();
                c.cycles = c.cycles.max(until);
                return Ok(());
            }
            self.step_once(until)?;
        }
        Ok(())
    }

    /// Runs for `seconds` of device time.
    pub fn run_for(&mut self, seconds: f64) -> Result<(), Stop> {
        let until = self.chip().cycles + (seconds * HZ as f64) as u64;
        self.run_until(until)
    }

    /// One stretch of the engine: exceptions taken, the engine run to the next event, the
    /// events fired.
    fn step_once(&mut self, until: u64) -> Result<(), Stop> {
        self.raise_lines();
        if let Some(n) = self.exception_to_take() {
            let pc = self.reg(R::PC);
            self.enter(n, pc).map_err(Stop::Lockup)?;
        } else if self.pending_masked() {
            // Pending but masked (PRIMASK or BASEPRI): taken as soon as the mask changes
            // (the block hook stops the run there), as the core takes it at the CPSIE or MSR
            // that unmasks it (ARMv7-M ARM B1.5.4), not at the next event.
            let mask = (self.reg(R::PRIMASK) & 1, self.reg(R::BASEPRI));
            self.uc.get_data_mut().masked_pending = Some(mask);
        }
        let next = self.next_event().min(until);
        let c = self.uc.get_data_mut();
        c.next_stop = next;
        let pc = self.reg(R::PC);
        // `until` at an address no fetch reaches (odd): 0 stopped the engine at the code an
        // image runs from SRAM1 remapped at 0.
        let r = self.uc.emu_start((pc | 1) as u64, 0xFFFF_FFFF, 0, 0);
        self.uc.get_data_mut().masked_pending = None;
        if let Some(it) = self.uc.get_data_mut().it_fix.take() {
            self.set_it_state(it).map_err(Stop::Lockup)?;
        }
        let pc = self.reg(R::PC);
        match r {
            Ok(()) => {
                // WFE/WFI: sleep to the next event unless the event register is set (WFE) or
                // something already wakes the core.
                if std::mem::take(&mut self.uc.get_data_mut().slept) {
                    // The WFE/WFI completes (the return address of what wakes it is the next
                    // instruction).
                    self.uc
                        .reg_write(R::PC, (pc + 2) as u64)
                        .map_err(|e| Stop::Lockup(err(e)))?;
                    self.chip_mut().add_instructions(1);
                    let event = std::mem::take(&mut self.uc.get_data_mut().event);
                    self.raise_lines();
                    if !event && !self.wakes() {
                        self.fire_events();
                        // An event due now (fired just above) may raise a line that wakes the
                        // core: it sleeps to the next event only if none did (the sense's DMA
                        // interrupt, due at the WFI, was taken a half period late at the
                        // timer's next event: a step past its deadline).
                        self.raise_lines();
                        if !self.wakes() {
                            let t = self.next_event().min(until);
                            let c = self.uc.get_data_mut();
                            if t > c.cycles {
                                c.cycles = t;
                            }
                        }
                    }
                }
            }
            Err(uc_error::EXCEPTION)
                if self.chip().semihost.is_some() && self.semihost_at(pc).is_some() =>
            {
                self.semihost_call(pc).map_err(Stop::Lockup)?;
            }
            // EXC_RETURN: the engine stops at the fetch (unmapped, or its own exception-exit
            // trap at 0xFFFFFFF0 and above).
            Err(uc_error::FETCH_UNMAPPED | uc_error::EXCEPTION) if pc >= 0xFFFF_FF00 => {
                self.exception_return(pc | 1).map_err(Stop::Lockup)?;
            }
            Err(e) => {
                let kind = match e {
                    uc_error::READ_UNMAPPED
                    | uc_error::WRITE_UNMAPPED
                    | uc_error::FETCH_UNMAPPED => exc::BUS_FAULT,
                    _ => exc::USAGE_FAULT,
                };
                let why = format!("{e:?} at pc {pc:#010x}");
                self.fault(kind, pc, &why)?;
            }
        }
        if let Some(at) = self.chip().fetch_unremapped {
            return Err(Stop::Lockup(format!(
                "code fetched at {at:#010x} without SRAM1 remapped at 0 (SYSCFG_MEMRMP.MEM_MODE \
                 not 11): the chip would run the flash's alias there"
            )));
        }
        if let Some(sp) = self.chip().guard_hit
            && !self
                .chip()
                .active
                .iter()
                .any(|a| a.exc == exc::MEM_MANAGE || a.exc == exc::HARD_FAULT)
            && self.chip().core.cfsr & 0x80 == 0
        {
            // The stack entered the guard: MemManage, data access violation at SP.
            let c = self.chip_mut();
            c.core.cfsr |= 0x82; // MMARVALID | DACCVIOL
            c.core.mmfar = sp;
            let pc = self.reg(R::PC);
            self.fault(exc::MEM_MANAGE, pc, "the stack entered the MPU guard")?;
        }
        self.fire_events();
        self.read_log();
        let c = self.chip();
        if c.core.reset_requested {
            self.system_reset(crate::periph::clock::CSR_SFTRSTF)
                .map_err(Stop::Lockup)?;
        }
        if let Some(t) = self.chip().p.iwdg.expires
            && self.chip().cycles >= t
        {
            // Where the image was when the watchdog bit: a hang's place.
            let pc = self.reg(R::PC);
            let active: Vec<u32> = self.chip().active.iter().map(|a| a.exc).collect();
            let line = format!(
                "{:.6} s: the watchdog reset the image at pc {pc:#010x} ({}), active exceptions \
                 {active:?}",
                self.seconds(),
                self.symbol_at(pc as u64)
            );
            if self.echo_log {
                eprintln!("rehost: {line}");
            }
            self.watchdog_resets.push(line);
            self.system_reset(crate::periph::clock::CSR_IWDGRSTF)
                .map_err(Stop::Lockup)?;
        }
        Ok(())
    }
}
