//! `rehost`: the shipped firmware image on an emulated STM32F4 (see the crate's docs).
//!
//! - `rehost boot ELF --board nucleo-f446 --seconds 1`: runs the image from reset and prints
//!   its decoded log and the figures of the run.
//! - `rehost serve ELF [--scenario PLANT.toml] [--flash FILE]`: the image's USART2 on a TCP
//!   port for `gms-tune --tcp`, on hil-sim's plant, its stored settings kept in FILE.
//! - `rehost check ELF --board BOARD`: the bench's first minutes on the image, held to the
//!   board's budgets.

use std::process::ExitCode;

use clap::{Parser, Subcommand};
use rehost::{Board, Machine, Options, TimeModel};

mod check;
mod serve;

#[derive(Parser)]
#[command(about = "The firmware image on an emulated STM32F4, its loop closed on hil-sim's plant")]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Runs the image from reset for a while and prints its log and figures.
    Boot {
        /// The firmware ELF (`cargo fw-f446` builds target/thumbv7em-none-eabihf/firmware/firmware).
        elf: std::path::PathBuf,
        /// The board it was built for: nucleo-f446 or f405 (default: read from the image).
        #[arg(long)]
        board: Option<String>,
        /// Device time to run \[s\].
        #[arg(long, default_value_t = 0.5)]
        seconds: f64,
        /// Cycles per instruction (with `--timing cpi`).
        #[arg(long, default_value_t = 1.5)]
        cpi: f64,
        /// The time model: `cycles` (the Cortex-M4's costs, the flash's wait states behind
        /// the accelerator: docs/rehost.md) or `cpi` (a fixed cycles per instruction, the
        /// older model, for comparison).
        #[arg(long, default_value = "cycles")]
        timing: String,
    },
    /// Runs the image with its link bridged to a TCP port: `gms-tune --tcp HOST:PORT` talks
    /// to the shipped firmware (one client at a time; the log on stderr). The Nucleo's link
    /// is its USART2; the F405's its USB, which an emulated host enumerates, opens (DTR) and
    /// carries over its bulk endpoints.
    Serve {
        /// The firmware ELF.
        elf: std::path::PathBuf,
        /// The board it was built for: nucleo-f446 or f405 (default: read from the image).
        #[arg(long)]
        board: Option<String>,
        /// The address to listen on.
        #[arg(long, default_value = "127.0.0.1:7879")]
        listen: String,
        /// Device time per second of wall time, at most (the emulator runs slower than the
        /// board on a slow machine, never faster than this).
        #[arg(long, default_value_t = 1.0)]
        speed: f64,
        /// The plant: a hil-sim scenario file (its `[plant]`; the image keeps its own
        /// settings); hil-sim's default plant without it.
        #[arg(long, value_name = "SCENARIO.toml")]
        scenario: Option<std::path::PathBuf>,
        /// The board's flash outside the image, kept in this file across runs (what `save`
        /// stored survives a restart, as on a board); none: erased at each start.
        #[arg(long, value_name = "FILE")]
        flash: Option<std::path::PathBuf>,
        /// The time model: `cycles` (the Cortex-M4's costs, the flash's wait states behind
        /// the accelerator: docs/rehost.md) or `cpi` (a fixed cycles per instruction, the
        /// older model, for comparison).
        #[arg(long, default_value = "cycles")]
        timing: String,
    },
    /// Runs a semihosted bare-metal program (`cargo target-bench`'s: its `calib` and `cost`
    /// lines then count cycles, SysTick on the core clock) in the Cortex-M4's costs and prints
    /// what it wrote; the exit status is its own.
    Bench {
        /// The program's ELF.
        elf: std::path::PathBuf,
        /// Device time to run at most \[s\].
        #[arg(long, default_value_t = 60.0)]
        seconds: f64,
    },
    /// The bench's first hour on the image: boot, status, enable, a move, a set of gains
    /// while moving, save, a power cycle, the setting back; the figures printed, the
    /// image's faults and its stack held to the board's limits (non-zero exit otherwise, with
    /// the decoded log).
    Check {
        /// The firmware ELF.
        elf: std::path::PathBuf,
        /// The board it was built for: nucleo-f446 (its link USART2) or f405 (USB, with an
        /// emulated host that enumerates it); default: read from the image.
        #[arg(long)]
        board: Option<String>,
        /// Print where the cycles go (by function): the `status` request's, and in each motion
        /// the control interrupt's runs over 90 % of its budget.
        #[arg(long)]
        profile: bool,
        /// The time model: `cycles` (the Cortex-M4's costs, the flash's wait states behind
        /// the accelerator: docs/rehost.md) or `cpi` (a fixed cycles per instruction, the
        /// older model, for comparison).
        #[arg(long, default_value = "cycles")]
        timing: String,
        /// The current loop's rate \[Hz\] the session runs at (`set rate.cur_hz` before it,
        /// the position loop at its default): the budget is 60 % of its period.
        #[arg(long, default_value_t = 40_000)]
        cur_hz: u64,
        /// A what-if for the `cycles` time model: the functions whose names contain NAME (repeat
        /// it) fetched as from SRAM remapped at 0 (the I-bus, no wait states), as if the image
        /// had put them there; the image is not changed. Measures what moving them would gain.
        #[arg(long, value_name = "NAME")]
        what_if_sram: Vec<String>,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("rehost: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> Result<(), String> {
    match cli.cmd {
        Cmd::Serve {
            elf,
            board,
            listen,
            speed,
            scenario,
            flash,
            timing,
        } => {
            let timing = TimeModel::parse(&timing)?;
            let (image, board) = load(&elf, board.as_deref())?;
            if !(speed > 0.0 && speed.is_finite()) {
                return Err(format!("--speed {speed}: must be above 0"));
            }
            let scenario = match scenario {
                Some(p) => {
                    let text = std::fs::read_to_string(&p)
                        .map_err(|e| format!("--scenario {}: {e}", p.display()))?;
                    Some(
                        hil_sim::scenario::Scenario::parse(&text, &p.display().to_string())
                            .map_err(|e| format!("--scenario {}: {e}", p.display()))?,
                    )
                }
                None => None,
            };
            let m = Machine::new(
                &image,
                board,
                Options {
                    echo_log: true,
                    scenario,
                    timing,
                    ..Options::default()
                },
            )?;
            serve::run(m, &listen, speed, flash.as_deref())
        }
        Cmd::Bench { elf, seconds } => {
            let image = std::fs::read(&elf).map_err(|e| format!("{}: {e}", elf.display()))?;
            // `cargo target-bench`'s image is built for QEMU's STM32F405 (netduinoplus2).
            let mut m = Machine::new(
                &image,
                Board::F405,
                Options {
                    semihosting: true,
                    ..Options::default()
                },
            )?;
            let (ok, text) = m.run_semihosted(seconds)?;
            print!("{text}");
            if ok {
                Ok(())
            } else {
                Err("the program exited with a failure".into())
            }
        }
        Cmd::Check {
            elf,
            board,
            profile,
            timing,
            cur_hz,
            what_if_sram,
        } => {
            let timing = TimeModel::parse(&timing)?;
            if !(1_000..=100_000).contains(&cur_hz) {
                return Err(format!("--cur-hz {cur_hz}: 1000 … 100000 Hz"));
            }
            if !what_if_sram.is_empty() && timing != TimeModel::Cycles {
                return Err("--what-if-sram needs --timing cycles".into());
            }
            let (image, board) = load(&elf, board.as_deref())?;
            let mut m = Machine::new(
                &image,
                board,
                Options {
                    timing,
                    ..Options::default()
                },
            )?;
            if !what_if_sram.is_empty() {
                let taken = m.fetch_as_sram(&what_if_sram)?;
                let bytes: u32 = taken.iter().map(|t| t.1).sum();
                println!(
                    "what if: {} functions, {bytes} bytes of code, fetched from SRAM (the image unchanged):",
                    taken.len()
                );
                for (name, n) in &taken {
                    println!("  {n:6} B  {name}");
                }
            }
            let r = check::run(&mut m, profile, cur_hz);
            if r.is_err() {
                eprintln!("the image's log:");
                for l in &m.log_lines {
                    eprintln!("  {l}");
                }
                for f in &m.faults {
                    eprintln!("  fault: {f}");
                }
                let c = m.chip();
                eprintln!(
                    "  flash: a write outside programming at {:?}; FLASH_SR {:#x}",
                    c.bad_flash_write,
                    c.p.flash.read(0x0C)
                );
                eprintln!("{}", check::control_cycles(&m, cur_hz));
            }
            r
        }
        Cmd::Boot {
            elf,
            board,
            seconds,
            cpi,
            timing,
        } => {
            let timing = match TimeModel::parse(&timing)? {
                TimeModel::Cpi(_) => TimeModel::Cpi(cpi),
                t => t,
            };
            let (image, board) = load(&elf, board.as_deref())?;
            let mut m = Machine::new(
                &image,
                board,
                Options {
                    timing,
                    echo_log: true,
                    ..Options::default()
                },
            )?;
            let wall = std::time::Instant::now();
            let r = m.run_for(seconds);
            let w = wall.elapsed().as_secs_f64();
            let c = m.chip();
            println!(
                "ran {:.3} s of device time in {:.2} s ({:.1} M instructions, {:.1} M/s); resets {}",
                m.seconds(),
                w,
                c.instructions as f64 / 1e6,
                c.instructions as f64 / 1e6 / w,
                m.resets
            );
            println!(
                "deepest stack {} B (exceptions active there: {:?}); guard hit at {:?}; CFSR {:#x}; active now {:?}",
                m.stack_depth(),
                c.sp_min_context,
                c.guard_hit,
                c.core.cfsr,
                m.active_exceptions()
            );
            let mut by: std::collections::BTreeMap<u32, (u64, u64, u64)> = Default::default();
            for h in &m.handled {
                let e = by.entry(h.exc).or_insert((0, 0, 0));
                e.0 += 1;
                e.1 += h.instructions;
                e.2 = e.2.max(h.instructions);
            }
            for (exc, (n, sum, max)) in by {
                println!(
                    "exception {exc:3}: {n:7} times, {:8.1} instructions mean, {max:6} max",
                    sum as f64 / n as f64
                );
            }
            println!("pc now {:#010x}", m.pc());
            if m.board() == Board::F405 {
                let h = m.usb_host();
                println!(
                    "USB host: {:?}, {} enumeration(s), DTR {}",
                    h.link, h.enumerations, h.dtr
                );
                for l in h.desc.describe() {
                    println!("  {l}");
                }
                for e in &h.errors {
                    println!("  USB error: {e}");
                }
            }
            for f in &m.faults {
                println!("{f}");
            }
            println!("PRIMASK held at most {} instructions", c.primask_max);
            if let Err(e) = r {
                return Err(format!("{e:?}"));
            }
            Ok(())
        }
    }
}

/// The image's bytes and the board named, or the one the image was built for.
fn load(elf: &std::path::Path, board: Option<&str>) -> Result<(Vec<u8>, Board), String> {
    let image = std::fs::read(elf).map_err(|e| format!("{}: {e}", elf.display()))?;
    let board = match board {
        Some(b) => Board::parse(b)?,
        None => Board::of_image(&image).ok_or_else(|| {
            format!(
                "{}: not a gms image rehost can tell the board of: name it with --board",
                elf.display()
            )
        })?,
    };
    Ok((image, board))
}
