//! `cargo target-bench`: builds `target-bench` for thumbv7em-none-eabihf, runs it on QEMU's
//! emulated STM32F405 (`netduinoplus2`, Cortex-M4F) with `-icount shift=0`, and prints one
//! line per figure, `<name> <instructions>`. Checks that the emulated chip computes gms-core's
//! self-test workload bit for bit as the host does, and the budgets
//! (`gms6_step` <= 300, `controller_step` and `controller_step_adaptive` <= 1500,
//! `device_period` — the device core's whole position period, two `ControlLoop::step` calls
//! with their bookkeeping — <= 2000 instructions).
//!
//! Exit status: 0 when everything holds; 1 when a budget is exceeded or the target's results
//! differ from the host's; 2 when the benchmark cannot run (no QEMU, build failure).
//! `--report-only` prints the budget check but does not fail on it (equivalence still does).
//!
//! Before the benchmark, `target-bench`'s `stack-guard` binary runs on the same emulated chip:
//! `f4_regs::mpu`'s stack guard and fault handlers, then a recursion that overflows the stack;
//! it must end in the guard's fault handler (`stack guard hit: CFSR …`), on a fresh stack.

use std::process::{Command, ExitCode};
use std::time::Duration;

mod elf;
mod stack;

// The boards' memory maps and probe-rs chip names, from the firmware's own files.
#[path = "../../gms-core/src/boards/f405/memory.rs"]
#[allow(dead_code)]
mod f405;
#[path = "../../gms-core/src/boards/nucleo_f446/memory.rs"]
#[allow(dead_code)]
mod nucleo_f446;

/// The boards: name (as in `--board`), cargo feature, probe-rs chip.
const BOARDS: [(&str, &str, &str); 2] = [
    ("f405", "board-f405", f405::PROBE_RS_CHIP),
    (
        "nucleo-f446",
        "board-nucleo-f446",
        nucleo_f446::PROBE_RS_CHIP,
    ),
];

/// The interrupts the F405 board's firmware handles (stm32-metapac 21 `Interrupt`: RM0090
/// table 61): the sense ADC's overrun, embassy's time driver, the deadman (TIM8's update),
/// the control interrupt (the sense DMA), USB.
const IRQS_F405: [(&str, u32); 5] = [
    ("ADC", 18),
    ("TIM4", 30),
    ("TIM8_UP_TIM13", 44),
    ("DMA2_STREAM0", 56),
    ("OTG_FS", 67),
];

/// The interrupts the NUCLEO-F446RE's firmware handles (the same numbers on the F446, RM0390
/// table 38): the F405's but USB, and the UART to the ST-LINK with its two DMA streams.
const IRQS_NUCLEO_F446: [(&str, u32); 7] = [
    ("DMA1_STREAM5", 16),
    ("DMA1_STREAM6", 17),
    ("ADC", 18),
    ("TIM4", 30),
    ("USART2", 38),
    ("TIM8_UP_TIM13", 44),
    ("DMA2_STREAM0", 56),
];

/// The boards' maps for `check-elf`.
const MAPS: [elf::BoardMap; 2] = [
    elf::BoardMap {
        name: "f405",
        app_len: f405::APP_LEN,
        ram_len: f405::RAM_LEN,
        store_start: f405::STORE_START,
        irqs: &IRQS_F405,
    },
    elf::BoardMap {
        name: "nucleo-f446",
        app_len: nucleo_f446::APP_LEN,
        ram_len: nucleo_f446::RAM_LEN,
        store_start: nucleo_f446::STORE_START,
        irqs: &IRQS_NUCLEO_F446,
    },
];

/// The budgets (instructions). The table's period is allowed 2,100: its bench drives the
/// current loop open (the sense reads a fixed 0.02 A), and since issue 55's duty limit (0.43 at
/// 40 kHz on the F405) the loop sits at that limit, which costs 2,076 where the same period
/// without the limit takes 1,934. The image's own table motion, closed on the plant, stays
/// within its cycle budget (`rehost check`: 2,418 of 2,520). Back to 2,000 is issue 54's.
const BUDGETS: [(&str, f64); 7] = [
    ("gms6_step", 300.0),
    ("controller_step", 1500.0),
    ("controller_step_adaptive", 1500.0),
    ("device_period", 2000.0),
    ("device_period_frf", 2000.0),
    ("device_period_map", 2000.0),
    ("device_period_table", 2100.0),
];

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("target-bench") => {
            let report_only = args.iter().any(|a| a == "--report-only");
            match target_bench(report_only) {
                Ok(code) => ExitCode::from(code),
                Err(e) => {
                    eprintln!("error: {e}");
                    ExitCode::from(2)
                }
            }
        }
        Some("check-elf") => match check_elf(&args[1..]) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("error: {e}");
                ExitCode::from(1)
            }
        },
        Some("flash") => match flash(&args[1..]) {
            Ok(code) => ExitCode::from(code),
            Err(e) => {
                eprintln!("error: {e}");
                ExitCode::from(2)
            }
        },
        _ => {
            eprintln!(
                "usage: cargo xtask target-bench [--report-only]\n       cargo xtask flash [--board f405|nucleo-f446] [--watchdog-check]\n       cargo xtask check-elf --board f405|nucleo-f446 ELF"
            );
            ExitCode::from(2)
        }
    }
}

/// `cargo xtask check-elf --board NAME ELF`: the static checks of `elf.rs` on a linked image.
fn check_elf(args: &[String]) -> Result<(), String> {
    let [flag, name, path] = args else {
        return Err("usage: cargo xtask check-elf --board f405|nucleo-f446 ELF".into());
    };
    if flag != "--board" {
        return Err("usage: cargo xtask check-elf --board f405|nucleo-f446 ELF".into());
    }
    let board = MAPS.iter().find(|m| m.name == name).ok_or_else(|| {
        let names: Vec<&str> = MAPS.iter().map(|m| m.name).collect();
        format!("unknown board {name:?} (boards: {})", names.join(", "))
    })?;
    let bytes = std::fs::read(path).map_err(|e| format!("cannot read {path}: {e}"))?;
    let lines = elf::check(board, &bytes).map_err(|e| format!("{path} (board {name}):\n{e}"))?;
    for l in lines {
        println!("{name}: {l}");
    }
    let listing = disassemble(path)?;
    let funcs = stack::parse(&listing);
    let mut bad = Vec::new();
    // No single step of the stack pointer may jump the stack guard (gms-core's
    // `hw::STACK_GUARD_BYTES`, `f4_regs::mpu`).
    let guard = gms_core::boards::hw::STACK_GUARD_BYTES as u64;
    if let Some((f, largest)) = funcs
        .iter()
        .map(|(n, f)| (n, f.largest_sub))
        .max_by_key(|(_, b)| *b)
    {
        println!("{name}: largest single stack step {largest} B (in {f}), guard {guard} B");
        if largest >= guard {
            bad.push(format!(
                "{f} steps the stack pointer by {largest} B at once, not less than the {guard} B \
                 guard: an overflow could jump it"
            ));
        }
    }
    for (root, limit) in HANDLER_STACK_LIMITS {
        if !funcs.contains_key(root) {
            bad.push(format!("{root}: not in the image"));
            continue;
        }
        let c = stack::chain(&funcs, root);
        println!(
            "{name}: {root}: worst stack {} B (limit {limit}) over {} functions, deepest {}; \
             {} indirect calls; BASEPRI accesses: {}{}",
            c.stack,
            c.reached,
            c.path.join(" > "),
            c.indirect,
            c.basepri.len(),
            if c.unknown.is_empty() {
                String::new()
            } else {
                format!("; not followed: {}", c.unknown.join(", "))
            }
        );
        if c.stack > limit {
            bad.push(format!("{root}: worst stack {} B above {limit}", c.stack));
        }
        for (f, insn) in &c.basepri {
            bad.push(format!("{root}: BASEPRI access in {f}: {insn}"));
        }
        if let Some(path) = &c.panic_path {
            bad.push(format!(
                "{root}: a panic is reachable: {}",
                path.join(" > ")
            ));
        }
        if c.indirect > 0 || !c.unknown.is_empty() {
            bad.push(format!(
                "{root}: {} indirect calls, not followed {:?}: the stack figure is a lower \
                 bound",
                c.indirect, c.unknown
            ));
        }
    }
    match stack_bound(&bytes, &funcs) {
        Ok(line) => println!("{name}: {line}"),
        Err(e) => bad.push(e),
    }
    if bad.is_empty() {
        Ok(())
    } else {
        Err(format!("{path} (board {name}):\n{}", bad.join("\n")))
    }
}

/// The handlers by the priority level they run at (`firmware/src/irq.rs`, `board.rs`), least
/// urgent first: one of each level can be active at once, nested on thread mode. The DMA
/// streams other than the link's and the control's are embassy's, at the drivers' level.
const NESTING: [(&str, &[&str]); 5] = [
    (
        "link (P4)",
        &["USART2", "DMA1_STREAM5", "DMA1_STREAM6", "OTG_FS"],
    ),
    ("drivers (P3)", &["TIM4", "DMA1_STREAM*", "DMA2_STREAM*"]),
    ("control (P1)", &["DMA2_STREAM0"]),
    ("deadman (P0)", &["TIM8_UP_TIM13", "ADC"]),
    // The NMI preempts the deadman too (priority −2).
    ("NMI", &["NonMaskableInt"]),
];

/// The stack the image can need at once against the stack above its guard: thread mode (the
/// executor's loop from `main` plus its deepest task, each `TaskStorage::poll`, which the
/// executor calls through a pointer) plus the worst handler of each priority level nested on
/// it. A chain through indirect calls is a lower bound, and said so.
fn stack_bound(
    bytes: &[u8],
    funcs: &std::collections::BTreeMap<String, stack::Function>,
) -> Result<String, String> {
    use object::{Object, ObjectSymbol};
    let file = object::File::parse(bytes).map_err(|e| format!("not an ELF file: {e}"))?;
    let sym = |n: &str| {
        file.symbols()
            .find(|s| s.name() == Ok(n))
            .map(|s| s.address())
    };
    let (Some(end), Some(start)) = (sym("_stack_end"), sym("_stack_start")) else {
        return Err("no _stack_end/_stack_start symbols (cortex-m-rt's)".into());
    };
    // Where the firmware puts its guard (`board::stack_guard`), by the same function.
    let guard = gms_core::boards::hw::STACK_GUARD_BYTES;
    let Some((guard_base, room)) = f4_regs::mpu::guard_region(end as u32, start as u32, guard, 0)
    else {
        return Err(format!(
            "no room for the {guard} B stack guard between {end:#010x} and {start:#010x}"
        ));
    };
    let (guard_top, room) = (guard_base as u64 + guard as u64, room as u64);
    let main = stack::chain(funcs, "main");
    let tasks: Vec<(&String, stack::Chain)> = funcs
        .keys()
        .filter(|n| n.contains("TaskStorage") && n.contains("4poll"))
        .map(|n| (n, stack::chain(funcs, n)))
        .collect();
    let task = tasks
        .iter()
        .map(|(_, c)| c.stack - stack::ENTRY_BYTES)
        .max()
        .unwrap_or(0);
    let thread = main.stack - stack::ENTRY_BYTES + task;
    let mut indirect = main.indirect + tasks.iter().map(|(_, c)| c.indirect).sum::<u32>();
    let mut total = thread;
    let mut parts = vec![format!("thread {thread} B ({} tasks)", tasks.len())];
    // A handler named at a level is not taken by another level's wildcard.
    let named: Vec<&str> = NESTING
        .iter()
        .flat_map(|(_, ns)| ns.iter().copied())
        .filter(|n| !n.ends_with('*'))
        .collect();
    let mut seen: Vec<&str> = Vec::new();
    for (level, names) in NESTING {
        let mut worst = 0;
        for (n, _) in funcs.iter() {
            let hit = names.iter().any(|p| match p.strip_suffix('*') {
                Some(prefix) => n.starts_with(prefix) && !named.contains(&n.as_str()),
                None => n == p,
            });
            if !hit || seen.contains(&n.as_str()) {
                continue;
            }
            seen.push(n.as_str());
            let c = stack::chain(funcs, n);
            indirect += c.indirect;
            worst = worst.max(c.stack);
        }
        total += worst;
        parts.push(format!("{level} {worst} B"));
    }
    let line = format!(
        "stack at once: {} = {total} B{}, of {room} B above the guard ({guard_top:#010x}..{start:#010x})",
        parts.join(" + "),
        if indirect > 0 {
            format!(" (a lower bound: {indirect} indirect calls not followed)")
        } else {
            String::new()
        }
    );
    if total > room { Err(line) } else { Ok(line) }
}

/// The handlers that run above the global critical section's mask, and the most stack each
/// may use with everything it calls \[bytes\]: they preempt whatever runs, so their stack
/// comes on top of the deepest of the rest.
/// Each is held free of any reachable panic too (the firmware's own handlers; embassy's
/// drivers' are not ours to hold).
const HANDLER_STACK_LIMITS: [(&str, u64); 4] = [
    ("DMA2_STREAM0", 8192),
    ("TIM8_UP_TIM13", 1024),
    ("ADC", 1024),
    ("NonMaskableInt", 1024),
];

/// The image's disassembly by rustup's `llvm-objdump` (`rustup component add llvm-tools`),
/// or the one `LLVM_OBJDUMP` names.
fn disassemble(path: &str) -> Result<String, String> {
    let tool = match std::env::var_os("LLVM_OBJDUMP") {
        Some(t) => std::path::PathBuf::from(t),
        None => {
            let out = Command::new("rustc")
                .args(["--print", "sysroot"])
                .output()
                .map_err(|e| format!("cannot run rustc: {e}"))?;
            let sysroot = String::from_utf8_lossy(&out.stdout).trim().to_string();
            let lib = std::path::Path::new(&sysroot).join("lib/rustlib");
            std::fs::read_dir(&lib)
                .map_err(|e| format!("{}: {e}", lib.display()))?
                .filter_map(|d| d.ok())
                .map(|d| d.path().join("bin/llvm-objdump"))
                .find(|p| p.exists())
                .ok_or("no llvm-objdump: rustup component add llvm-tools")?
        }
    };
    let out = Command::new(&tool)
        .args(["-d", "--no-show-raw-insn", path])
        .output()
        .map_err(|e| format!("cannot run {}: {e}", tool.display()))?;
    if !out.status.success() {
        return Err(format!(
            "{} failed: {}",
            tool.display(),
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// `cargo xtask flash [--board NAME] [--watchdog-check]`: builds the firmware for the board
/// (default f405; with the bench's watchdog check, the firmware feature `watchdog-check`) and
/// runs it with probe-rs (`probe-rs run --chip CHIP`: flashes, resets, prints the defmt log).
fn flash(args: &[String]) -> Result<u8, String> {
    let usage = "usage: cargo xtask flash [--board f405|nucleo-f446] [--watchdog-check]";
    let check = args.iter().any(|a| a == "--watchdog-check");
    let rest: Vec<&String> = args.iter().filter(|a| *a != "--watchdog-check").collect();
    let name = match rest.as_slice() {
        [] => "f405",
        [flag, name] if *flag == "--board" => name.as_str(),
        _ => return Err(usage.into()),
    };
    let (_, feature, chip) = BOARDS.iter().find(|b| b.0 == name).ok_or_else(|| {
        let names: Vec<&str> = BOARDS.iter().map(|b| b.0).collect();
        format!("unknown board {name:?} (boards: {})", names.join(", "))
    })?;
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let status = Command::new(&cargo)
        .args([
            "build",
            "-p",
            "firmware",
            "--profile",
            "firmware",
            "--target",
            "thumbv7em-none-eabihf",
            "--no-default-features",
            "--features",
            &if check {
                format!("{feature},watchdog-check")
            } else {
                feature.to_string()
            },
        ])
        .status()
        .map_err(|e| format!("cannot run cargo: {e}"))?;
    if !status.success() {
        return Err(format!("building the firmware for {name} failed"));
    }
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let target_dir = std::env::var("CARGO_TARGET_DIR")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|_| root.join("target"));
    let elf = target_dir.join("thumbv7em-none-eabihf/firmware/firmware");
    let status = Command::new("probe-rs")
        .args(["run", "--chip", chip])
        .arg(&elf)
        .status()
        .map_err(|e| {
            format!("cannot run probe-rs ({e}); install it: cargo install probe-rs-tools")
        })?;
    Ok(if status.success() { 0 } else { 1 })
}

/// The `cost` lines of a target-bench run, per call: ticks over calls, divided by the
/// `calib` line's ticks per instruction when `calibrated` (QEMU's icount), as they are
/// otherwise (rehost's SysTick: cycles); `gms6_step` added first as the larger of its
/// sticking and slipping figures.
fn costs(text: &str, calibrated: bool) -> Result<Vec<(String, f64)>, String> {
    let mut per_tick = if calibrated { None } else { Some(1.0) };
    let mut figures: Vec<(String, f64)> = Vec::new();
    for line in text.lines() {
        match line.split_whitespace().collect::<Vec<_>>().as_slice() {
            ["calib", ticks, instr] if calibrated => {
                let (t, i): (f64, f64) = (parse(ticks)?, parse(instr)?);
                per_tick = Some(t / i);
            }
            ["cost", name, ticks, calls] => {
                let r = per_tick.ok_or("cost before calib")?;
                let n = parse::<f64>(ticks)? / r / parse::<f64>(calls)?;
                figures.push((name.to_string(), n));
            }
            _ => {}
        }
    }
    if let (Some(a), Some(b)) = (
        get(&figures, "gms6_step_sticking"),
        get(&figures, "gms6_step_slipping"),
    ) {
        figures.insert(0, ("gms6_step".into(), a.max(b)));
    }
    Ok(figures)
}

/// The figure named `n`.
fn get(figs: &[(String, f64)], n: &str) -> Option<f64> {
    figs.iter().find(|f| f.0 == n).map(|f| f.1)
}

/// Runs `elf` on QEMU's `netduinoplus2` (Cortex-M4F) with semihosting, `-icount shift=0`
/// when `icount` (every instruction 1 ns of virtual time), at most 120 s of host time; whether
/// it exited with success, and what it printed (stdout, then stderr).
fn qemu(elf: &std::path::Path, icount: bool) -> Result<(bool, String), String> {
    let mut args = vec![
        "-machine",
        "netduinoplus2",
        "-cpu",
        "cortex-m4",
        "-nographic",
        "-monitor",
        "none",
        "-serial",
        "none",
        "-semihosting-config",
        "enable=on,target=native",
    ];
    if icount {
        args.extend(["-icount", "shift=0"]);
    }
    let mut child = Command::new("qemu-system-arm")
        .args(&args)
        .arg("-kernel")
        .arg(elf)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .map_err(|e| {
            format!("cannot run qemu-system-arm ({e}); install it: apt-get install qemu-system-arm")
        })?;
    // A watchdog: each run takes well under a second of host time.
    let deadline = std::time::Instant::now() + Duration::from_secs(120);
    loop {
        match child.try_wait() {
            Ok(Some(_)) => break,
            Ok(None) if std::time::Instant::now() > deadline => {
                let _ = child.kill();
                return Err(format!(
                    "qemu did not finish {} within 120 s",
                    elf.display()
                ));
            }
            Ok(None) => std::thread::sleep(Duration::from_millis(20)),
            Err(e) => return Err(format!("waiting for qemu: {e}")),
        }
    }
    let out = child
        .wait_with_output()
        .map_err(|e| format!("reading qemu's output: {e}"))?;
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    Ok((out.status.success(), text))
}

fn target_bench(report_only: bool) -> Result<u8, String> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let status = Command::new(&cargo)
        .args([
            "build",
            "-q",
            "-p",
            "target-bench",
            "--profile",
            "firmware",
            "--target",
            "thumbv7em-none-eabihf",
        ])
        .status()
        .map_err(|e| format!("cannot run cargo: {e}"))?;
    if !status.success() {
        return Err("building target-bench for thumbv7em-none-eabihf failed".into());
    }
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let target_dir = std::env::var("CARGO_TARGET_DIR")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|_| root.join("target"));
    let elf = target_dir.join("thumbv7em-none-eabihf/firmware/target-bench");
    // The stack guard first: its own binary, a recursion that must fault into it.
    let guard = target_dir.join("thumbv7em-none-eabihf/firmware/stack-guard");
    let (ok, text) = qemu(&guard, false)?;
    let hit = text.lines().find(|l| l.starts_with("stack guard hit:"));
    match (ok, hit) {
        (true, Some(line)) => println!("{line}"),
        _ => {
            return Err(format!(
                "the stack guard did not stop the overflow on the target: {}",
                text.trim()
            ));
        }
    }
    let (ok, text) = qemu(&elf, true)?;
    if !ok || !text.lines().any(|l| l == "done") {
        return Err(format!(
            "the benchmark failed on the target: {}",
            text.trim()
        ));
    }
    // QEMU's ticks are instructions times the calibration's ratio.
    let figures = costs(&text, true)?;
    let mut target_hashes: Vec<(String, u64)> = Vec::new();
    for line in text.lines() {
        if let ["equiv", name, hash] = line.split_whitespace().collect::<Vec<_>>().as_slice() {
            target_hashes.push((name.to_string(), parse(hash)?));
        }
    }
    for (name, n) in &figures {
        println!("{name} {}", n.round() as u64);
    }
    // The same program in rehost's cycle model (the Cortex-M4's costs, the flash's 5 wait
    // states behind the accelerator, SysTick on the core clock: ticks are cycles), beside the
    // instruction counts; rehost is built by CI's earlier steps (`cargo build -p rehost`).
    let rehost = target_dir.join(format!("debug/rehost{}", std::env::consts::EXE_SUFFIX));
    if rehost.is_file() {
        let out = Command::new(&rehost)
            .arg("bench")
            .arg(&elf)
            .output()
            .map_err(|e| format!("cannot run {}: {e}", rehost.display()))?;
        let text = String::from_utf8_lossy(&out.stdout);
        if !out.status.success() || !text.lines().any(|l| l == "done") {
            return Err(format!(
                "the benchmark failed in rehost: {}{}",
                text.trim(),
                String::from_utf8_lossy(&out.stderr).trim()
            ));
        }
        // rehost's ticks are cycles.
        let cycles = costs(&text, false)?;
        for (name, c) in &cycles {
            let per = get(&figures, name).map_or(String::new(), |n| {
                format!(" ({:.2} per instruction)", c / n.max(1.0))
            });
            println!("cycles {name} {}{per}", c.round() as u64);
        }
    } else {
        println!(
            "cycles: not counted ({} not built: cargo build -p rehost)",
            rehost.display()
        );
    }
    let mut code = 0u8;
    // Host/target equivalence: the same workload, the same bits.
    let host = [
        ("friction", gms_core::selftest::friction_hash(20_000)),
        ("controller", gms_core::selftest::controller_hash(5_000)),
    ];
    for (name, h) in host {
        match target_hashes.iter().find(|t| t.0 == name) {
            Some((_, t)) if *t == h => println!("equivalence_{name} identical {h:016x}"),
            Some((_, t)) => {
                println!("equivalence_{name} DIFFERS host {h:016x} target {t:016x}");
                code = 1;
            }
            None => return Err(format!("the target printed no {name} hash")),
        }
    }
    for (name, budget) in BUDGETS {
        match get(&figures, name) {
            Some(n) if n.round() <= budget => {
                println!("budget {name} ok ({} <= {budget})", n.round())
            }
            Some(n) => {
                println!("budget {name} EXCEEDED ({} > {budget})", n.round());
                if !report_only {
                    code = 1;
                }
            }
            None => return Err(format!("no figure for {name}")),
        }
    }
    Ok(code)
}

fn parse<T: std::str::FromStr>(s: &str) -> Result<T, String> {
    s.parse()
        .map_err(|_| format!("unexpected number in the target's output: {s:?}"))
}
