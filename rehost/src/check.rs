//! `rehost check`: the scripted session against the image (see `main.rs`).

use rehost::{Board, Machine};

/// The control interrupt's exception number (DMA2 stream 0, IRQ 56).
const CONTROL: u32 = 16 + 56;

fn expect_ok(m: &mut Machine, line: &str, seconds: f64) -> Result<Vec<String>, String> {
    let reply = m.request(line, seconds)?;
    match reply.last() {
        Some(l) if l.starts_with("ok") => {
            println!("> {line}\n< {}", reply.join("\n< "));
            Ok(reply)
        }
        _ => Err(format!("`{line}` answered {reply:?}")),
    }
}

fn stats(v: &[u64]) -> (f64, u64) {
    let mean = v.iter().sum::<u64>() as f64 / v.len().max(1) as f64;
    (mean, v.iter().copied().max().unwrap_or(0))
}

/// Runs the session; an error names the first thing that went wrong.
pub fn run(m: &mut Machine, profile: bool) -> Result<(), String> {
    m.run_until_logged("control loop running", 1.0)?;
    println!("booted: \"control loop running\" at {:.4} s", m.seconds());
    if m.board() == Board::F405 {
        m.run_for(0.5).map_err(|e| format!("{e:?}"))?;
        return report(m, 0);
    }
    let thread0 = m.chip().thread_instructions;
    if profile {
        m.start_profile();
    }
    let st = expect_ok(m, "status", 0.5)?;
    println!(
        "the `status` request and reply: {} instructions of thread mode",
        m.chip().thread_instructions - thread0
    );
    if profile {
        for (f, n) in m.take_profile().iter().take(15) {
            println!("  {n:9} {f}");
        }
    }
    if !st.last().is_some_and(|l| l.contains("enabled=0")) {
        return Err(format!("status after boot: {st:?}"));
    }
    let enable_at = m.chip().cycles;
    expect_ok(m, "enable", 0.5)?;
    println!(
        "the periods from the `enable` on: {} instructions at most",
        stats(&m.instructions_of(CONTROL, enable_at)).1
    );
    m.run_for(0.05).map_err(|e| format!("{e:?}"))?;
    let moving_from = m.chip().cycles;
    expect_ok(m, "move 0.02", 0.5)?;
    m.run_for(0.05).map_err(|e| format!("{e:?}"))?;
    expect_ok(m, "status", 0.5)?;
    let set_at = m.chip().cycles;
    expect_ok(m, "set pos.kp 0.65", 0.5)?;
    let set_steps = m.instructions_of(CONTROL, set_at);
    m.run_for(0.1).map_err(|e| format!("{e:?}"))?;
    let st = expect_ok(m, "status", 0.5)?;
    let moving = m.instructions_of(CONTROL, moving_from);
    let (mean, max) = stats(&moving);
    println!(
        "control interrupt while moving: {} periods, {mean:.0} instructions mean, {max} max; \
         the periods from the `set` on: {} max",
        moving.len(),
        stats(&set_steps).1
    );
    let faulted = st
        .last()
        .is_some_and(|l| !l.contains("faults=0 ") && !l.contains("faults=none"));
    if faulted || !st.last().is_some_and(|l| l.contains("enabled=1")) {
        println!("(the axis faulted or stopped while moving: {st:?})");
    }
    expect_ok(m, "disable", 0.5)?;
    expect_ok(m, "save", 3.0)?;
    m.power_cycle()?;
    m.run_until_logged("control loop running", 1.0)
        .map_err(|e| format!("after the power cycle: {e}"))?;
    let kp = expect_ok(m, "get pos.kp", 0.5)?;
    if !kp.last().is_some_and(|l| l.contains("0.65")) {
        return Err(format!("pos.kp after save and a power cycle: {kp:?}"));
    }
    report(m, max)
}

fn report(m: &Machine, _moving_max: u64) -> Result<(), String> {
    let all = m.instructions_of(CONTROL, 0);
    let (mean, max) = stats(&all);
    let c = m.chip();
    println!(
        "{:.3} s of device time: {:.1} M instructions; control interrupt {} times, {mean:.0} mean, {max} max; \
         deepest stack {} B; PRIMASK held at most {} instructions; resets {}",
        m.seconds(),
        c.instructions as f64 / 1e6,
        all.len(),
        m.stack_depth(),
        c.primask_max,
        m.resets
    );
    println!(
        "the longest PRIMASK hold began in {}",
        m.symbol_at(c.primask_max_at)
    );
    if let Some(sp) = c.guard_hit {
        return Err(format!("the stack entered the MPU guard (SP {sp:#010x})"));
    }
    if !m.faults.is_empty() {
        return Err(format!("faults: {:?}", m.faults));
    }
    if m.logged("control_stall") {
        return Err("the supervisor reported control_stall".into());
    }
    Ok(())
}
