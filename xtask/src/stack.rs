//! Static checks of interrupt handlers' code, from the image's disassembly (`llvm-objdump`,
//! rustup's `llvm-tools` component): for a handler and every function it can reach through
//! direct calls and tail calls, no access to BASEPRI (the global critical section's mask,
//! `firmware/src/irq.rs`: a handler above the mask that wrote it would break the sections of
//! the code it preempts), and the worst stack the chain can use (each function's pushes,
//! `vpush`es and `sub sp`, summed along the deepest path, plus the 104 bytes the core stacks
//! on entry with the FPU's context, ARMv7-M ARM B1.5.7). Indirect calls (`blx rN`) cannot be
//! followed: they are counted and reported. The walk stops at the panic handler (its own
//! frame counted): it never returns, and it masks every interrupt and switches the bridge off
//! before anything else (`firmware/src/main.rs`), so what it calls afterwards — the log line,
//! which takes the critical section — cannot break a section it preempted.

/// Whether the walk stops at `name` (the panic handler, `rust_begin_unwind`).
pub fn terminal(name: &str) -> bool {
    name.contains("rust_begin_unwind")
}

use std::collections::{BTreeMap, BTreeSet};

/// One function of the disassembly.
#[derive(Debug, Default, Clone)]
pub struct Function {
    /// Bytes its own code puts on the stack.
    pub frame: u64,
    /// Functions it calls or tail-calls directly.
    pub calls: BTreeSet<String>,
    /// Indirect calls.
    pub indirect: u32,
    /// Instructions that read or write BASEPRI (or BASEPRI_MAX).
    pub basepri: Vec<String>,
    /// Its largest single `sub sp` \[bytes\]: a step of the stack pointer with no access,
    /// which a stack guard must be larger than.
    pub largest_sub: u64,
}

/// The functions of an `llvm-objdump -d --no-show-raw-insn` listing, by name.
pub fn parse(listing: &str) -> BTreeMap<String, Function> {
    let mut out: BTreeMap<String, Function> = BTreeMap::new();
    let mut current: Option<String> = None;
    for line in listing.lines() {
        let t = line.trim_end();
        // A function: "08000288 <DMA2_STREAM0>:".
        if let Some(name) = t
            .strip_suffix(">:")
            .and_then(|s| s.split_once(" <"))
            .filter(|(addr, _)| addr.chars().all(|c| c.is_ascii_hexdigit()))
            .map(|(_, n)| n.to_string())
        {
            out.entry(name.clone()).or_default();
            current = Some(name);
            continue;
        }
        let Some(name) = current.as_ref() else {
            continue;
        };
        // An instruction: " 8000288:      \tpush\t{r4, r5, r6, r7, lr}".
        let Some((_, insn)) = t.split_once(":") else {
            continue;
        };
        let mut parts = insn.split_whitespace();
        let Some(mnemonic) = parts.next() else {
            continue;
        };
        let operands: String = parts.collect::<Vec<_>>().join(" ");
        let f = out.entry(name.clone()).or_default();
        let bytes = frame_bytes(mnemonic, &operands);
        f.frame += bytes;
        if mnemonic.starts_with("sub") {
            f.largest_sub = f.largest_sub.max(bytes);
        }
        let lower = operands.to_ascii_lowercase();
        if (mnemonic == "msr" || mnemonic == "mrs") && lower.contains("basepri") {
            f.basepri.push(format!("{mnemonic} {operands}"));
        }
        if mnemonic == "blx" && !operands.contains('<') {
            f.indirect += 1;
        }
        let is_branch = mnemonic == "bl"
            || mnemonic == "blx"
            || mnemonic == "b"
            || mnemonic == "b.w"
            || (mnemonic.starts_with('b') && mnemonic.ends_with(".w") && mnemonic.len() == 5);
        if is_branch
            && let Some(target) = operands
                .split_once('<')
                .and_then(|(_, r)| r.split_once('>'))
                .map(|(t, _)| t)
        {
            // A branch inside the function is "<name+0x..>"; another function's entry is
            // "<other>" (or "<other+0x..>" for a jump into it, kept as a call too).
            let callee = target.split('+').next().unwrap_or(target);
            if callee != name.as_str() {
                f.calls.insert(callee.to_string());
            }
        }
    }
    out
}

/// Bytes one instruction puts on the stack.
fn frame_bytes(mnemonic: &str, operands: &str) -> u64 {
    let regs = |ops: &str| -> u64 {
        ops.split_once('{')
            .and_then(|(_, r)| r.split_once('}'))
            .map(|(list, _)| list.split(',').filter(|r| !r.trim().is_empty()).count() as u64)
            .unwrap_or(0)
    };
    match mnemonic {
        "push" | "push.w" => 4 * regs(operands),
        "stmdb" | "stmdb.w" if operands.starts_with("sp!") => 4 * regs(operands),
        "vpush" | "vpush.64" | "vpush.32" => {
            let size = if operands.contains("{d") { 8 } else { 4 };
            size * regs(operands)
        }
        "sub" | "sub.w" | "subw" if operands.starts_with("sp,") => operands
            .rsplit_once('#')
            .and_then(|(_, n)| {
                let n = n.trim();
                match n.strip_prefix("0x") {
                    Some(h) => u64::from_str_radix(h, 16).ok(),
                    None => n.parse().ok(),
                }
            })
            .unwrap_or(0),
        _ => 0,
    }
}

/// What a handler's chain does.
#[derive(Debug, Default)]
pub struct Chain {
    /// The deepest stack \[bytes\], the 104 bytes of exception entry included.
    pub stack: u64,
    /// The path to it.
    pub path: Vec<String>,
    /// Functions reached.
    pub reached: usize,
    /// Indirect calls in the chain.
    pub indirect: u32,
    /// BASEPRI accesses in the chain: (function, instruction).
    pub basepri: Vec<(String, String)>,
    /// Calls to functions the listing does not hold, or a recursion: the figure is then a
    /// lower bound.
    pub unknown: Vec<String>,
    /// A path from the root to the panic handler, if one is reachable by direct calls.
    pub panic_path: Option<Vec<String>>,
}

/// The bytes an exception entry stacks with the FPU's context (ARMv7-M: 8 words, plus 18 of
/// FP state with lazy stacking reserving the room).
pub const ENTRY_BYTES: u64 = 104;

/// The chain from `root`.
pub fn chain(funcs: &BTreeMap<String, Function>, root: &str) -> Chain {
    let mut c = Chain::default();
    let mut memo: BTreeMap<String, (u64, Vec<String>)> = BTreeMap::new();
    let mut seen = BTreeSet::new();
    let mut on_path = Vec::new();
    let (depth, path) = deepest(funcs, root, &mut memo, &mut on_path, &mut c.unknown);
    c.stack = depth + ENTRY_BYTES;
    c.path = path;
    let mut todo = vec![root.to_string()];
    let mut parent: BTreeMap<String, String> = BTreeMap::new();
    while let Some(n) = todo.pop() {
        if !seen.insert(n.clone()) {
            continue;
        }
        if let Some(f) = funcs.get(&n) {
            if terminal(&n) {
                if c.panic_path.is_none() {
                    let mut path = vec![n.clone()];
                    let mut at = &n;
                    while let Some(p) = parent.get(at) {
                        path.push(p.clone());
                        at = p;
                    }
                    path.reverse();
                    c.panic_path = Some(path);
                }
                continue;
            }
            for callee in &f.calls {
                if !seen.contains(callee) {
                    parent.entry(callee.clone()).or_insert_with(|| n.clone());
                }
            }
            c.indirect += f.indirect;
            for b in &f.basepri {
                c.basepri.push((n.clone(), b.clone()));
            }
            todo.extend(f.calls.iter().cloned());
        }
    }
    c.reached = seen.len();
    c
}

fn deepest(
    funcs: &BTreeMap<String, Function>,
    name: &str,
    memo: &mut BTreeMap<String, (u64, Vec<String>)>,
    on_path: &mut Vec<String>,
    unknown: &mut Vec<String>,
) -> (u64, Vec<String>) {
    if let Some(m) = memo.get(name) {
        return m.clone();
    }
    let Some(f) = funcs.get(name) else {
        unknown.push(format!("{name} (not in the listing)"));
        return (0, vec![name.to_string()]);
    };
    if on_path.iter().any(|n| n == name) {
        unknown.push(format!("{name} (recursion)"));
        return (0, vec![name.to_string()]);
    }
    on_path.push(name.to_string());
    let mut best = (0, Vec::new());
    let callees = if terminal(name) {
        BTreeSet::new()
    } else {
        f.calls.clone()
    };
    for callee in &callees {
        let d = deepest(funcs, callee, memo, on_path, unknown);
        if d.0 > best.0 || best.1.is_empty() {
            best = d;
        }
    }
    on_path.pop();
    let mut path = vec![name.to_string()];
    path.extend(best.1);
    let r = (f.frame + best.0, path);
    memo.insert(name.to_string(), r.clone());
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    const LISTING: &str = "\
08000288 <ISR>:
 8000288:      \tpush\t{r4, r5, r6, r7, lr}
 800028c:      \tpush.w\t{r8, r9, r10, r11}
 8000292:      \tvpush\t{d8, d9}
 8000296:      \tsub.w\tsp, sp, #0x100
 800029a:      \tsub\tsp, #0x8
 800029c:      \tbl\t0x8000400 <leaf>
 80002a0:      \tbeq\t0x800033a <ISR+0xb2> @ imm = #0x8a
 80002a4:      \tb.w\t0x8000500 <tail>
 80002a8:      \tblx\tr3
08000400 <leaf>:
 8000400:      \tpush\t{r7, lr}
 8000402:      \tmrs\tr0, basepri
 8000404:      \tpop\t{r7, pc}
08000500 <tail>:
 8000500:      \tsub\tsp, #0x400
 8000502:      \tbl\t0x8000600 <elsewhere>
 8000504:      \tbl\t0x8000700 <_RNvCs1_7___rustc17rust_begin_unwind>
08000700 <_RNvCs1_7___rustc17rust_begin_unwind>:
 8000700:      \tpush\t{r7, lr}
 8000702:      \tmsr\tbasepri_max, r1
 8000704:      \tbl\t0x8000800 <deep>
08000800 <deep>:
 8000800:      \tsub\tsp, #0x1000
";

    #[test]
    fn frames_calls_and_basepri_of_a_listing() {
        let f = parse(LISTING);
        // 5 + 4 registers, two D registers, 0x100 + 8.
        assert_eq!(f["ISR"].frame, 36 + 16 + 256 + 8);
        assert_eq!(
            f["ISR"].calls,
            ["leaf", "tail"].iter().map(|s| s.to_string()).collect()
        );
        assert_eq!(f["ISR"].indirect, 1);
        assert_eq!(f["leaf"].frame, 8);
        assert_eq!(f["ISR"].largest_sub, 256);
        assert_eq!(f["tail"].largest_sub, 1024);
        assert_eq!(f["leaf"].basepri, vec!["mrs r0, basepri".to_string()]);
        let c = chain(&f, "ISR");
        // The deepest path: ISR then tail (1024) rather than leaf (8), then the panic
        // handler's own frame (8; what it calls is not followed).
        assert_eq!(c.stack, 316 + 1024 + 8 + ENTRY_BYTES);
        assert_eq!(
            c.path,
            vec!["ISR", "tail", "_RNvCs1_7___rustc17rust_begin_unwind"]
        );
        assert_eq!(c.basepri.len(), 1);
        assert_eq!(c.indirect, 1);
        assert_eq!(
            c.unknown,
            vec!["elsewhere (not in the listing)".to_string()]
        );
        // The panic handler is reachable, through `tail`; from `leaf` it is not.
        assert_eq!(
            c.panic_path,
            Some(
                ["ISR", "tail", "_RNvCs1_7___rustc17rust_begin_unwind"]
                    .iter()
                    .map(|s| s.to_string())
                    .collect()
            )
        );
        assert_eq!(chain(&f, "leaf").panic_path, None);
    }
}
