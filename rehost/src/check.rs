//! `rehost check`: the scripted session against the image (see `main.rs`), its figures, and
//! the budgets they are held to.

use rehost::machine::HZ;
use rehost::{Board, Machine};

/// The control interrupt's exception number (DMA2 stream 0, IRQ 56).
const CONTROL: u32 = 16 + 56;

/// A control period's instructions, at most, the steps that take a request included (a
/// parameter set hands its running state over there, in a current step without a position
/// step): at 1.5 cycles an instruction 3,000 cycles, 17.9 µs at 168 MHz, within the board's
/// budget at the default 40 kHz current loop (75 % of the 25 µs period: 18.75 µs, 3,150
/// cycles, past which the image latches `overrun`).
const STEP_BUDGET: u64 = 2_000;
/// PRIMASK held, at most \[instructions\]: 200 cycles at 1.5 cycles an instruction (the
/// deadman's wait; the mailbox's lock does not hold it: firmware `irq.rs`).
const PRIMASK_BUDGET: u64 = 133;
/// The control interrupt held off by a mask in a context it would preempt (thread mode's
/// critical sections), at most \[instructions\]: 200 cycles. The step starts when the sense
/// window ends, 5.2 µs after the PWM's bottom, and must end before the next, 19.8 µs (3,326
/// cycles) later at 40 kHz: the step's 2,000 instructions (3,000 cycles) and this delay fit.
const HELD_BUDGET: u64 = 133;
/// A `status` request and its reply, and a telemetry line, at most \[instructions of thread
/// mode\].
const STATUS_BUDGET: u64 = 50_000;
/// The stack above the guard the image may use, at most \[bytes\]: 32 KiB less the 2 KiB the
/// supervisor keeps as its margin.
const STACK_BUDGET: u32 = 30 * 1024;

/// The session: the image and the windows of device time in which it took requests.
struct Session<'m> {
    m: &'m mut Machine,
    /// (from, to) \[cycles\] of each request, from its first byte to its reply.
    windows: Vec<(u64, u64)>,
}

impl Session<'_> {
    fn run_for(&mut self, seconds: f64) -> Result<(), String> {
        self.m.run_for(seconds).map_err(|e| format!("{e:?}"))
    }

    /// `status`, which must say the bridge drives without a fault; its reply line. `what`
    /// names what came before, for the error.
    fn driving(&mut self, what: &str) -> Result<String, String> {
        let st = self.ok("status", 0.5)?;
        let last = st.last().cloned().unwrap_or_default();
        if !(last.contains("enabled=1") && last.contains("faults=0 ")) {
            return Err(format!("{what} faulted the axis: {last}"));
        }
        Ok(last)
    }

    /// Runs `f`; with `profile`, prints where the control interrupt's runs of more than
    /// `over` instructions went meanwhile, under `title`.
    fn profiled<T>(
        &mut self,
        profile: bool,
        over: u64,
        title: &str,
        f: impl FnOnce(&mut Self) -> Result<T, String>,
    ) -> Result<T, String> {
        if profile {
            self.m.start_profile_over(Some(CONTROL), over);
        }
        let r = f(self)?;
        if profile {
            profile_print(self.m, title);
        }
        Ok(r)
    }

    /// Sends `line`; its reply must end `ok`.
    fn ok(&mut self, line: &str, seconds: f64) -> Result<Vec<String>, String> {
        let from = self.m.chip().cycles;
        let reply = self.m.request(line, seconds)?;
        let to = self.m.chip().cycles;
        // The step that takes a request is within a period or two of the reply.
        self.windows.push((from, to + 2 * HZ / 20_000));
        let (_, max) = stats(&self.m.instructions_of(CONTROL, from));
        match reply.last() {
            Some(l) if l.starts_with("ok") => {
                println!(
                    "> {line}   [the control interrupt meanwhile: {max} instructions at most]\n< {}",
                    reply.join("\n< ")
                );
                Ok(reply)
            }
            _ => Err(format!("`{line}` answered {reply:?}")),
        }
    }
}

/// The times of a stream's sample lines `#t=… ref=… pos=… error=… ff=… current=…
/// friction=…`: each whole line must carry the seven fields as numbers, the times increasing (the first line may
/// be a tail, the last unfinished).
fn stream_times(text: &str) -> Result<Vec<f64>, String> {
    let mut lines: Vec<&str> = text.split('\n').collect();
    lines.pop();
    let mut ts = Vec::new();
    for (k, l) in lines.iter().enumerate() {
        let fields: Vec<(&str, f64)> = l
            .trim_start_matches('#')
            .split_whitespace()
            .filter_map(|w| w.split_once('='))
            .filter_map(|(key, v)| v.parse::<f64>().ok().map(|v| (key, v)))
            .collect();
        let keys: Vec<&str> = fields.iter().map(|f| f.0).collect();
        if keys != ["t", "ref", "pos", "error", "ff", "current", "friction"] || !l.starts_with('#')
        {
            if k == 0 {
                continue;
            }
            return Err(format!("a stream line cut or garbled: {l:?}"));
        }
        let t = fields[0].1;
        if ts.last().is_some_and(|&last| t <= last) {
            return Err(format!("a stream line out of order: {l:?}"));
        }
        ts.push(t);
    }
    Ok(ts)
}

fn stats(v: &[u64]) -> (f64, u64) {
    let mean = v.iter().sum::<u64>() as f64 / v.len().max(1) as f64;
    (mean, v.iter().copied().max().unwrap_or(0))
}

fn profile_print(m: &mut Machine, title: &str) {
    println!("{title}");
    for (f, n) in m.take_profile().iter().take(15) {
        println!("  {n:9} {f}");
    }
}

/// Runs the session; an error names the first thing that went wrong or the budget missed.
pub fn run(m: &mut Machine, profile: bool) -> Result<(), String> {
    m.run_until_logged("control loop running", 1.0)?;
    // From here the interrupt is the loop's, at its priority: a critical section below it
    // delays a step.
    m.chip_mut().watch = Some(CONTROL);
    println!("booted: \"control loop running\" at {:.4} s", m.seconds());
    let mut s = Session {
        m,
        windows: Vec::new(),
    };
    let mut status_cost = 0;
    if s.m.board() == Board::NucleoF446 {
        status_cost = session(&mut s, profile)?;
    } else {
        // The F405's link (USB) is not modelled: the image boots and runs.
        s.run_for(0.5)?;
    }
    budgets(&s, status_cost)
}

/// The bench's first minutes over the Nucleo's UART; returns the `status` request's cost.
fn session(s: &mut Session<'_>, profile: bool) -> Result<u64, String> {
    // An empty line (a host flushing the line first, as gms-tune does) gets no reply and
    // changes nothing.
    s.m.send_to_image(b"\n");
    s.run_for(0.01)?;
    if !s.m.take_from_image().is_empty() || !s.m.faults.is_empty() || s.m.logged("panic") {
        return Err("an empty line was answered, or faulted the image".into());
    }
    let thread0 = s.m.chip().thread_instructions;
    if profile {
        s.m.start_profile(None);
    }
    let st = s.ok("status", 0.5)?;
    let status_cost = s.m.chip().thread_instructions - thread0;
    println!("the `status` request and reply: {status_cost} instructions of thread mode");
    if profile {
        profile_print(s.m, "where they went:");
    }
    if !st.last().is_some_and(|l| l.contains("enabled=0")) {
        return Err(format!("status after boot: {st:?}"));
    }
    s.ok("enable", 0.5)?;
    s.run_for(0.05)?;
    let moving_from = s.m.chip().cycles;
    s.profiled(
        profile,
        1700,
        "the control interrupt's runs over 1,700 instructions while moving:",
        |s| {
            s.ok("move 0.02", 0.5)?;
            s.run_for(0.05)
        },
    )?;
    s.driving("a `move`")?;
    s.profiled(
        profile,
        STEP_BUDGET,
        "the control interrupt's runs over the step budget while the `set` is taken:",
        |s| s.ok("set pos.kp 0.65", 0.5),
    )?;
    s.run_for(0.1)?;
    let last = s.driving("a `set` while moving")?;
    if !last.contains("pos=0.0199") && !last.contains("pos=0.02") {
        return Err(format!("the move did not end at 0.02 rad: {last}"));
    }
    // A friction change while moving, that the running state does not fit: Fs lowered to
    // just above Fc shrinks every block's limit (alpha_i Fs) below the forces of the slow
    // slide, so the hand-over clamps them (its slow path, in the step that takes the set).
    s.ok("move 0", 0.5)?;
    s.run_for(0.03)?;
    s.ok("set gms.fs 0.000126", 0.5)?;
    s.run_for(0.15)?;
    let last = s.driving("a friction `set` while moving")?;
    if !last.contains("pos=0 ") && !last.contains("pos=0.0000") && !last.contains("pos=-0.0000") {
        return Err(format!("the move back did not end at 0: {last}"));
    }
    s.ok("set gms.fs 0.00022", 0.5)?;
    // A capture while holding, every field that is computed rather than copied and a mean,
    // read back in full chunks (32 samples of four fields: 128 values, the largest copy a
    // request step makes).
    s.profiled(
        profile,
        STEP_BUDGET - 100,
        "the control interrupt's runs within 100 instructions of the budget while capturing:",
        |s| {
            s.ok("capture t,pos,ref,current_mean 1 200", 0.5)?;
            s.run_for(0.01)
        },
    )?;
    for start in [0, 32] {
        s.ok(&format!("capture read {start} 32"), 0.5)?;
    }
    s.ok("capture off", 0.5)?;
    // A frequency response point, as commissioning's open-loop measurement runs it (the
    // injection and the demodulation in every position step).
    s.profiled(
        profile,
        STEP_BUDGET - 300,
        "the control interrupt's runs within 300 instructions of the budget measuring a frequency response:",
        |s| {
            s.ok("frf current 20 0.003 4 1", 0.5)?;
            s.run_for(0.15)?;
            // Its report read while it runs (thread mode copies the loop's report under the
            // mailbox's lock).
            s.ok("frf", 0.5)?;
            s.run_for(0.15)
        },
    )?;
    s.ok("frf off", 0.5)?;
    s.driving("a frequency response")?;
    // The window's stream (its seven fields at 1 kHz, about 90 kB/s against the UART's 92):
    // the requests are still read and answered between its batches.
    const WINDOW: f64 = 0.3;
    s.ok("stream t,ref,pos,error,ff,current,friction 1000", 0.5)?;
    let _ = s.m.take_from_image();
    let thread0 = s.m.chip().thread_instructions;
    let line0 = s.m.chip().p.usart2.line_busy_cycles();
    s.run_for(WINDOW)?;
    let busy = (s.m.chip().p.usart2.line_busy_cycles() - line0) as f64 / (WINDOW * HZ as f64);
    // The telemetry's cost: all thread-mode instructions of the window (the link's polling
    // too) over the sample lines sent.
    let text = String::from_utf8_lossy(&s.m.take_from_image()).to_string();
    let lines = text.bytes().filter(|&b| b == b'\n').count() as u64;
    let per_line = (s.m.chip().thread_instructions - thread0) / lines.max(1);
    // Every line whole: the seven fields, numbers, in time order (the first line may be the
    // tail of one the window began in, the last one unfinished). Samples the link could not
    // carry are left out at the source (the telemetry queue full), never cut on the line.
    let ts = stream_times(&text)?;
    let gaps = ts.windows(2).filter(|w| w[1] - w[0] > 1.5e-3).count();
    println!(
        "the window's stream: {lines} sample lines in {WINDOW} s of 1 kHz, {per_line} \
         instructions of thread mode each; the UART busy {:.0} % of the time at {} baud; every \
         line whole and in order; {gaps} gaps where the queue dropped samples",
        busy * 100.0,
        gms_core::protocol::UART_BAUD
    );
    if (lines as f64) < 0.5 * WINDOW * 1000.0 || per_line > STATUS_BUDGET {
        return Err(format!(
            "the stream sent {lines} lines in {WINDOW} s at {per_line} instructions each \
             (budget {STATUS_BUDGET})"
        ));
    }
    s.ok("status", 0.5)
        .map_err(|e| format!("with the stream saturating the link: {e}"))?;
    s.ok("stream off", 0.5)?;
    s.run_for(0.02)?;
    // A speed with a sweep, as identification's runs start it (a capture armed for it,
    // from the hold its gains were set in), then a hold: the steps that take them within
    // the budget, no fault.
    s.ok("capture t,pos,current_mean,volts_mean 3 100 next", 0.5)?;
    s.profiled(
        profile,
        STEP_BUDGET - 150,
        "the control interrupt's runs within 150 instructions of the budget as a swept speed starts:",
        |s| s.ok("velocity 1 0 1 1 0.2", 0.5),
    )?;
    s.run_for(0.05)?;
    s.ok("capture off", 0.5)?;
    s.ok("hold", 0.5)?;
    s.run_for(0.05)?;
    s.driving("a speed and a hold")?;
    let _ = s.m.take_from_image();
    let moving = s.m.instructions_of(CONTROL, moving_from);
    let (mean, max) = stats(&moving);
    println!(
        "control interrupt while moving: {} periods, {mean:.0} instructions mean, {max} max",
        moving.len()
    );
    s.ok("disable", 0.5)?;
    s.ok("save", 3.0)?;
    s.m.power_cycle()?;
    s.m.run_until_logged("control loop running", 1.0)
        .map_err(|e| format!("after the power cycle: {e}"))?;
    let kp = s.ok("get pos.kp", 0.5)?;
    if !kp.last().is_some_and(|l| l.contains("0.65")) {
        return Err(format!("pos.kp after save and a power cycle: {kp:?}"));
    }
    if s.m.logged("control_stall") {
        return Err("the supervisor reported control_stall".into());
    }
    // The HSE fails while the axis holds: the clock security system's NMI switches the bridge
    // off at once, and the supervisor says why.
    s.ok("enable", 0.5)?;
    s.run_for(0.01)?;
    if !s.m.bridge_on() {
        return Err("the bridge is not on after `enable`".into());
    }
    s.m.hse_fails();
    s.run_for(0.0002)?;
    if s.m.bridge_on() {
        return Err("the HSE failed and the bridge stayed on".into());
    }
    s.m.run_until_logged("the HSE failed", 0.5)
        .map_err(|e| format!("the HSE failed: {e}"))?;
    println!(
        "the HSE failed: bridge off within 0.2 ms, \"control_stall: the HSE failed …\" logged"
    );
    // The supervisor no longer feeds the watchdog: a reset within its 4 s, then the start-up
    // finds no HSE within its bound and stops there, the bridge pins untouched.
    let resets = s.m.resets;
    s.m.run_until_logged("no HSE", 5.0)
        .map_err(|e| format!("after the HSE failed: {e}"))?;
    if s.m.resets != resets + 1 {
        return Err(format!(
            "after the HSE failed: {} resets, one by the watchdog expected",
            s.m.resets - resets
        ));
    }
    println!(
        "then the watchdog reset at {:.2} s and the start-up stopped: \"no HSE … Stopped here\"",
        s.m.seconds()
    );
    Ok(status_cost)
}

/// The control interrupt's runs so far in cycles (their entry and return included), against
/// the period at the default 40 kHz, with the time model and thread mode's share.
pub fn control_cycles(m: &Machine) -> String {
    let c = m.chip();
    let cyc: Vec<u64> = m
        .handled
        .iter()
        .filter(|h| h.exc == CONTROL)
        .map(|h| h.cycles)
        .collect();
    let (cmean, cmax) = stats(&cyc);
    let period = HZ / 40_000;
    let model = match c.model {
        rehost::TimeModel::Cpi(cpi) => format!("{cpi} cycles per instruction"),
        rehost::TimeModel::Cycles => "the Cortex-M4's costs and the flash's wait states".into(),
    };
    format!(
        "the control interrupt in cycles ({model}): {} runs, {cmean:.0} mean, {cmax} at most: \
         {:.0} % and {:.0} % of the {period}-cycle period at 40 kHz; thread mode {:.0} % of the \
         time awake",
        cyc.len(),
        100.0 * cmean / period as f64,
        100.0 * cmax as f64 / period as f64,
        100.0 * c.thread_cycles as f64 / c.cycles.max(1) as f64,
    )
}

/// The run's figures, and the budgets they are held to.
fn budgets(s: &Session<'_>, status_cost: u64) -> Result<(), String> {
    let m = &*s.m;
    let all: Vec<(u64, u64)> = m
        .handled
        .iter()
        .filter(|h| h.exc == CONTROL)
        .map(|h| (h.at, h.instructions))
        .collect();
    let in_request = |at: u64| s.windows.iter().any(|&(a, b)| at >= a && at <= b);
    let steady = all
        .iter()
        .filter(|(at, _)| !in_request(*at))
        .map(|&(_, n)| n)
        .max()
        .unwrap_or(0);
    let requests = all
        .iter()
        .filter(|(at, _)| in_request(*at))
        .map(|&(_, n)| n)
        .max()
        .unwrap_or(0);
    let (mean, _) = stats(&all.iter().map(|&(_, n)| n).collect::<Vec<_>>());
    let c = m.chip();
    println!("{}", control_cycles(m));
    if c.model == rehost::TimeModel::Cycles {
        let (sp, a) = (c.timing.spent, c.timing.art.stats);
        println!(
            "where the cycles went: instructions {:.1} M, taken branches {:.1} M, the flash's \
             wait states {:.1} M (instruction lines {} hits, {} misses; data lines {} hits, {} \
             misses), exception entry and return {:.1} M",
            sp.instructions as f64 / 1e6,
            sp.branches as f64 / 1e6,
            sp.flash as f64 / 1e6,
            a.i_hits,
            a.i_misses,
            a.d_hits,
            a.d_misses,
            sp.exceptions as f64 / 1e6
        );
    }
    println!(
        "{:.3} s of device time, {:.1} M instructions, {} resets; the control interrupt {} \
         times: {mean:.0} instructions mean, {steady} at most outside requests (budget \
         {STEP_BUDGET}), {requests} at most in the steps taking them (the same budget); deepest stack {} B (budget {STACK_BUDGET}); PRIMASK held \
         {} instructions at most (budget {PRIMASK_BUDGET}; from {} at {:#010x}); the control interrupt held off by a mask \
         {} instructions at most (budget {HELD_BUDGET}; from {} at {:#010x})",
        m.seconds(),
        c.instructions as f64 / 1e6,
        m.resets,
        all.len(),
        m.stack_depth(),
        c.primask_max,
        m.symbol_at(c.primask_max_at),
        c.primask_max_at,
        c.held_max,
        m.symbol_at(c.held_max_at),
        c.held_max_at
    );
    let mut over = Vec::new();
    if let Some(sp) = c.guard_hit {
        over.push(format!("the stack entered the MPU guard (SP {sp:#010x})"));
    }
    if !m.faults.is_empty() {
        over.push(format!("faults: {:?}", m.faults));
    }
    if m.board() == Board::F405 && m.logged("control_stall") {
        over.push("the supervisor reported control_stall".into());
    }
    if steady > STEP_BUDGET {
        over.push(format!("a control period of {steady} instructions"));
    }
    if requests > STEP_BUDGET {
        over.push(format!(
            "a request-taking period of {requests} instructions"
        ));
    }
    if m.stack_depth() > STACK_BUDGET {
        over.push(format!("{} B of stack", m.stack_depth()));
    }
    if c.primask_max > PRIMASK_BUDGET {
        over.push(format!("PRIMASK held {} instructions", c.primask_max));
    }
    if c.held_max > HELD_BUDGET {
        over.push(format!(
            "the control interrupt held off {} instructions",
            c.held_max
        ));
    }
    if c.dr_reads_under_dma > 0 {
        over.push(format!(
            "{} reads of USART2's DR by the CPU while its DMA received (each could take a byte \
             from under the DMA)",
            c.dr_reads_under_dma
        ));
    }
    if status_cost > STATUS_BUDGET {
        over.push(format!("a status reply of {status_cost} instructions"));
    }
    if over.is_empty() {
        Ok(())
    } else {
        Err(over.join("; "))
    }
}
