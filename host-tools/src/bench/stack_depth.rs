//! The drive image's worst-case stack, read from its ELF: each function's frame from its
//! prologue (`push`, `vpush`, `str rX, [sp, #-N]!`, `sub sp, #N`), the call graph from its
//! branches (`bl`, a branch out of the function: a tail call, counted with the caller's frame
//! still on the stack, which over-estimates), and the deepest path from the reset handler and
//! from every interrupt handler. The firmware's interrupts nest (the sampling interrupt
//! preempts the housekeeping executor, which preempts the link's), so the worst case adds every
//! handler's deepest path and an exception frame for each (with the FPU's registers) to the
//! thread's. The disassembly is `llvm-objdump`'s (apt `llvm`; `scripts/fw` installs it).
//!
//! Indirect calls (`blx rN`, `bx rN`) may reach any function whose address the image holds (in
//! a literal pool, `.rodata`, `.data` or built by `movw`/`movt`) but a task's poll, and an
//! executor's run loop the poll functions of the tasks it runs ([`EXECUTORS`]) as well: without
//! that split every task would nest in every other (through a waker or a formatter).
//! Recursion through them (core's formatting, defmt's) is cut where a path meets a function
//! already on it, and reported: the bound is over paths that do not repeat a function
//! (nearly: a deepest path found while other members of a recursive group were on the path is
//! memoised and reused from another entry into the group, so the figure can depend on the
//! visiting order there; on today's images reversing the order gives the same figures, and
//! the groups' frames are small: 192 and 136 bytes on the drive image). Writes to `sp` the
//! analysis does not know (`sub sp, rN`, `mov sp, rN`) fail it.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::Path;
use std::process::Command;

use anyhow::{bail, Context, Result};
use serde::Serialize;

use crate::bench::elf_sections::section_headers;

/// Bytes an exception adds to the stack it interrupts: eight core registers and, with the FPU
/// in use, 18 more words (S0–S15, FPSCR, a reserved word), and up to 4 bytes of alignment.
pub const EXCEPTION_FRAME_BYTES: u32 = 26 * 4 + 4;

/// The firmware's executors: the function that runs each (a fragment of its symbol) and the
/// tasks it polls (fragments of their poll functions' symbols). A task poll no executor names
/// fails the analysis (a new task must say where it runs).
pub const EXECUTORS: &[(&str, &[&str])] = &[
    // The thread-mode executor of `#[embassy_executor::main]`: main and the link task.
    ("thread::Executor>::run", &["embassy_main_task", "link_task"]),
    // The housekeeping executor, run in the UART4 interrupt.
    ("UART4", &["position_tick_task"]),
];

/// One path of calls: its bytes and the functions on it with their frames.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct StackPath {
    pub bytes: u32,
    pub functions: Vec<(String, u32)>,
}

/// The image's worst case.
#[derive(Clone, Debug, Serialize)]
pub struct StackBound {
    /// From the reset handler (main, the thread executor and its tasks).
    pub thread: StackPath,
    /// Every interrupt and exception handler's deepest path.
    pub handlers: Vec<(String, StackPath)>,
    /// The thread's path, every handler's and an exception frame for each handler.
    pub worst: u32,
    /// The stack's size: `_stack_start − _stack_end`.
    pub stack: u32,
    /// Recursive groups of functions (cut; see the module's documentation).
    pub cycles: Vec<Vec<String>>,
}

impl StackBound {
    /// The worst case fits the stack.
    pub fn fits(&self) -> bool {
        self.worst <= self.stack
    }

    /// The thread's path and the named handlers' (by a part of their names, case-insensitive),
    /// each with its exception frame: the bound of a program in which only those fire.
    pub fn running_bound(&self, handler_names: &str) -> u32 {
        let wanted = handler_names.to_ascii_lowercase();
        self.thread.bytes
            + self
                .handlers
                .iter()
                .filter(|(name, _)| name.to_ascii_lowercase().contains(&wanted))
                .map(|(_, p)| p.bytes + EXCEPTION_FRAME_BYTES)
                .sum::<u32>()
    }
}

/// A function of the image: where it starts, its size, its name.
#[derive(Clone, Debug)]
pub struct Function {
    pub start: u32,
    pub size: u32,
    pub name: String,
}

/// What the disassembly says of each function (indexed as the functions).
#[derive(Clone, Debug, Default)]
pub struct CallGraph {
    pub frames: Vec<u32>,
    pub calls: Vec<BTreeSet<usize>>,
    pub indirect: Vec<bool>,
    /// Functions whose address the image holds.
    pub address_taken: BTreeSet<usize>,
}

/// Functions of `llvm-nm -C -S -n --defined-only` (text symbols with a size; demangled names
/// hold spaces), sorted by address.
pub fn functions(nm: &str) -> Vec<Function> {
    let mut f: Vec<Function> = nm
        .lines()
        .filter_map(|l| {
            let mut w = l.splitn(4, ' ');
            let (start, size, kind, name) = (w.next()?, w.next()?, w.next()?, w.next()?);
            let (start, size) = (u32::from_str_radix(start, 16).ok()?, u32::from_str_radix(size, 16).ok()?);
            (matches!(kind, "t" | "T") && size > 0).then(|| Function { start, size, name: name.to_string() })
        })
        .collect();
    f.sort_by_key(|x| x.start);
    f
}

/// An absolute symbol's address from `llvm-nm` (e.g. `_stack_start`).
pub fn symbol(nm: &str, name: &str) -> Option<u32> {
    nm.lines().find_map(|l| {
        let w: Vec<&str> = l.split_whitespace().collect();
        (w.last() == Some(&name)).then(|| u32::from_str_radix(w[0], 16).ok()).flatten()
    })
}

fn owner(functions: &[Function], address: u32) -> Option<usize> {
    let i = functions.partition_point(|f| f.start <= address).checked_sub(1)?;
    (address < functions[i].start + functions[i].size).then_some(i)
}

fn registers(operands: &str) -> u32 {
    operands.split(|c: char| !c.is_ascii_alphanumeric()).filter(|w| !w.is_empty()).count() as u32
}

fn immediate(s: &str) -> Option<u32> {
    let s = s.trim().strip_prefix('#')?;
    match s.strip_prefix("0x") {
        Some(h) => u32::from_str_radix(h, 16).ok(),
        None => s.parse().ok(),
    }
}

fn branch_target(operands: &str) -> Option<u32> {
    u32::from_str_radix(operands.split_whitespace().next()?.strip_prefix("0x")?, 16).ok()
}

/// The call graph from `llvm-objdump -d --no-show-raw-insn` and the words of the data
/// sections (`data_words`: every aligned word of `.rodata` and `.data`).
pub fn call_graph(functions: &[Function], disassembly: &str, data_words: &[u32]) -> Result<CallGraph> {
    let n = functions.len();
    let mut g = CallGraph {
        frames: vec![0; n],
        calls: vec![BTreeSet::new(); n],
        indirect: vec![false; n],
        address_taken: BTreeSet::new(),
    };
    let mut words: BTreeSet<u32> = data_words.iter().copied().collect();
    let mut low_halves: HashMap<String, u32> = HashMap::new();
    for line in disassembly.lines() {
        let Some((address, rest)) = line.split_once(':') else { continue };
        let Ok(address) = u32::from_str_radix(address.trim(), 16) else { continue };
        // `address: [raw bytes\t]mnemonic\toperands[ @ comment]` (data shows its bytes).
        let mut fields = rest.split('@').next().unwrap_or("").split('\t').map(str::trim).filter(|s| !s.is_empty());
        let mut mnemonic = fields.next().unwrap_or("");
        if mnemonic.split(' ').all(|b| b.len() == 2 && b.bytes().all(|c| c.is_ascii_hexdigit())) {
            mnemonic = fields.next().unwrap_or("");
        }
        let operands = fields.next().unwrap_or("");
        if mnemonic == ".word" {
            if let Some(w) = branch_target(operands) {
                words.insert(w);
            }
            continue;
        }
        let Some(f) = owner(functions, address) else { continue };
        let (first, second) = operands.split_once(',').map(|(a, b)| (a.trim(), b.trim())).unwrap_or((operands, ""));
        match mnemonic {
            "push" | "push.w" => g.frames[f] += 4 * registers(operands),
            "vpush" | "vpush.64" | "vpush.32" => {
                let each = if operands.contains('d') { 8 } else { 4 };
                g.frames[f] += each * registers(operands);
            }
            "movw" => {
                if let Some(v) = immediate(second) {
                    low_halves.insert(first.to_string(), v);
                }
            }
            "movt" => {
                if let (Some(low), Some(high)) = (low_halves.get(first), immediate(second)) {
                    words.insert(low | high << 16);
                }
            }
            "bl" | "blx" if branch_target(operands).is_some() => {
                let t = branch_target(operands).unwrap_or(0);
                g.calls[f].insert(owner(functions, t).with_context(|| format!("call to {t:#x} outside any function"))?);
            }
            "blx" | "bx" if operands != "lr" => g.indirect[f] = true,
            m if m.starts_with('b') && branch_target(operands).is_some() => {
                let t = branch_target(operands).unwrap_or(0);
                match owner(functions, t) {
                    Some(h) if h != f => {
                        g.calls[f].insert(h);
                    }
                    Some(_) => {}
                    None => bail!("branch to {t:#x} outside any function at {address:#x}"),
                }
            }
            m if m.starts_with("str") && operands.contains("[sp, #-") && operands.ends_with("]!") => {
                let n = operands.rsplit("#-").next().and_then(|s| s.trim_end_matches("]!").parse::<u32>().ok());
                g.frames[f] += n.with_context(|| format!("a store to the stack not understood: {line}"))?;
            }
            m if first == "sp" && (m.starts_with("sub") || m.starts_with("mov") || m.starts_with("ldr")) => {
                let amount = operands.rsplit(',').next().and_then(immediate);
                match amount {
                    Some(v) if m.starts_with("sub") => g.frames[f] += v,
                    _ => bail!("a write to sp the analysis does not know: {line}"),
                }
            }
            _ => {}
        }
    }
    g.address_taken = (0..n).filter(|&i| words.contains(&(functions[i].start | 1))).collect();
    Ok(g)
}

/// Who may call whom: direct calls, and each indirect call's possible targets (see the
/// module's documentation).
pub fn successors(functions: &[Function], g: &CallGraph) -> Result<Vec<BTreeSet<usize>>> {
    let polls: BTreeSet<usize> =
        g.address_taken.iter().copied().filter(|&i| functions[i].name.contains("TaskStorage")).collect();
    let mut polled_by: HashMap<usize, BTreeSet<usize>> = HashMap::new();
    for &p in &polls {
        let runs = |tasks: &[&str]| tasks.iter().any(|t| functions[p].name.contains(t));
        let Some((runner, _)) = EXECUTORS.iter().find(|(_, tasks)| runs(tasks)) else {
            bail!("the task poll {} runs in no executor the analysis knows (EXECUTORS)", functions[p].name)
        };
        let runners = (0..functions.len()).filter(|&i| g.indirect[i] && functions[i].name.contains(runner));
        let mut any = false;
        for r in runners {
            polled_by.entry(r).or_default().insert(p);
            any = true;
        }
        if !any {
            bail!("no function with an indirect call is named like the executor {runner}");
        }
    }
    let others: BTreeSet<usize> = g.address_taken.difference(&polls).copied().collect();
    Ok((0..functions.len())
        .map(|f| {
            let mut s = g.calls[f].clone();
            if g.indirect[f] {
                s.extend(others.iter().copied());
                s.extend(polled_by.get(&f).into_iter().flatten().copied());
            }
            s
        })
        .collect())
}

/// The deepest path from `root`, and the recursive groups met (cut where a path would repeat
/// a function). Depth-first over paths with a memo per function: a memoised result was found
/// with some functions on the path excluded, so a cut can only shorten a path that recursion
/// would make unbounded anyway; the groups are reported.
pub fn deepest(functions: &[Function], frames: &[u32], succ: &[BTreeSet<usize>], root: usize) -> StackPath {
    fn walk(
        f: usize,
        frames: &[u32],
        succ: &[BTreeSet<usize>],
        on_path: &mut Vec<bool>,
        memo: &mut HashMap<usize, (u32, Vec<usize>)>,
    ) -> (u32, Vec<usize>) {
        if let Some(m) = memo.get(&f) {
            return m.clone();
        }
        on_path[f] = true;
        let mut best = (0, Vec::new());
        for &g in &succ[f] {
            if on_path[g] {
                continue;
            }
            let d = walk(g, frames, succ, on_path, memo);
            if d.0 > best.0 {
                best = d;
            }
        }
        on_path[f] = false;
        let mut path = vec![f];
        path.extend(best.1);
        let r = (frames[f] + best.0, path);
        memo.insert(f, r.clone());
        r
    }
    let mut on_path = vec![false; functions.len()];
    let (bytes, path) = walk(root, frames, succ, &mut on_path, &mut HashMap::new());
    StackPath { bytes, functions: path.into_iter().map(|i| (functions[i].name.clone(), frames[i])).collect() }
}

/// Groups of functions that may call themselves (strongly connected components with a cycle).
pub fn recursive_groups(functions: &[Function], succ: &[BTreeSet<usize>]) -> Vec<Vec<String>> {
    // Kosaraju: finish order on the graph, then components on the reversed graph.
    let n = succ.len();
    let mut order = Vec::with_capacity(n);
    let mut seen = vec![false; n];
    for s in 0..n {
        if seen[s] {
            continue;
        }
        let mut stack = vec![(s, succ[s].iter().copied().collect::<Vec<_>>().into_iter())];
        seen[s] = true;
        while let Some((v, it)) = stack.last_mut() {
            let v = *v;
            match it.next() {
                Some(w) if !seen[w] => {
                    seen[w] = true;
                    stack.push((w, succ[w].iter().copied().collect::<Vec<_>>().into_iter()));
                }
                Some(_) => {}
                None => {
                    order.push(v);
                    stack.pop();
                }
            }
        }
    }
    let mut reverse = vec![Vec::new(); n];
    for (v, s) in succ.iter().enumerate() {
        for &w in s {
            reverse[w].push(v);
        }
    }
    let mut component = vec![usize::MAX; n];
    let mut groups = Vec::new();
    for &s in order.iter().rev() {
        if component[s] != usize::MAX {
            continue;
        }
        let id = groups.len();
        let mut members = vec![s];
        component[s] = id;
        let mut todo = vec![s];
        while let Some(v) = todo.pop() {
            for &w in &reverse[v] {
                if component[w] == usize::MAX {
                    component[w] = id;
                    members.push(w);
                    todo.push(w);
                }
            }
        }
        groups.push(members);
    }
    groups
        .into_iter()
        .filter(|g| g.len() > 1 || succ[g[0]].contains(&g[0]))
        .map(|g| {
            let mut names: Vec<String> = g.iter().map(|&i| functions[i].name.clone()).collect();
            names.sort();
            names
        })
        .collect()
}

fn run(tool: &str, args: &[&str], elf: &Path) -> Result<String> {
    let out = Command::new(tool)
        .args(args)
        .arg(elf)
        .output()
        .with_context(|| format!("cannot run {tool} (apt llvm; scripts/fw installs it)"))?;
    if !out.status.success() {
        bail!("{tool} failed: {}", String::from_utf8_lossy(&out.stderr));
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// The aligned words of `.rodata` and `.data`, and the vector table's entries (after the
/// initial stack pointer), from the ELF's section contents.
fn section_words(elf: &[u8]) -> (Vec<u32>, Vec<u32>) {
    let (mut data, mut vectors) = (Vec::new(), Vec::new());
    for section in section_headers(elf) {
        // Not PROGBITS (.bss, .uninit) or not in the file: no words.
        let Some(bytes) = section.contents(elf) else { continue };
        let words = bytes.chunks_exact(4).map(|w| u32::from_le_bytes([w[0], w[1], w[2], w[3]]));
        match section.name.as_str() {
            ".rodata" | ".data" => data.extend(words),
            ".vector_table" => vectors.extend(words.skip(1)),
            _ => {}
        }
    }
    (data, vectors)
}

/// What the analysis needs to know of an image beyond its ELF: its reset handler and the
/// symbols at its stack's top and low end.
#[derive(Clone, Copy, Debug)]
pub struct ImageLayout {
    pub reset: &'static str,
    pub stack_top: &'static str,
    pub stack_low: &'static str,
}

/// The drive image: cortex-m-rt's names.
pub const DRIVE_IMAGE: ImageLayout = ImageLayout { reset: "Reset", stack_top: "_stack_start", stack_low: "_stack_end" };

/// The QEMU programs of `fw/core-vectors` (their own runtime and linker script).
pub const CORE_VECTORS_IMAGE: ImageLayout = ImageLayout { reset: "reset", stack_top: "_stack_top", stack_low: "_ebss" };

/// The worst case of the ELF image at `elf` (see the module's documentation).
pub fn stack_bound(elf: &Path, layout: ImageLayout) -> Result<StackBound> {
    let nm = run("llvm-nm", &["-C", "-S", "-n", "--defined-only"], elf)?;
    let disassembly = run("llvm-objdump", &["-d", "--no-show-raw-insn"], elf)?;
    let bytes = std::fs::read(elf).with_context(|| format!("cannot read {}", elf.display()))?;
    let (data, vectors) = section_words(&bytes);
    let functions = functions(&nm);
    let graph = call_graph(&functions, &disassembly, &data)?;
    let succ = successors(&functions, &graph)?;
    let stack = match (symbol(&nm, layout.stack_top), symbol(&nm, layout.stack_low)) {
        (Some(top), Some(low)) if top >= low => top - low,
        _ => bail!("no {}/{} in {}", layout.stack_top, layout.stack_low, elf.display()),
    };
    let reset = functions.iter().position(|f| f.name == layout.reset).context("no reset handler")?;
    let thread = deepest(&functions, &graph.frames, &succ, reset);
    // Every distinct handler of the vector table but the reset handler (each may interrupt
    // the others: counted once each, which over-estimates handlers of one priority).
    let mut handlers = BTreeMap::new();
    for v in vectors.into_iter().filter(|&v| v & 1 == 1) {
        if let Some(h) = owner(&functions, v & !1).filter(|&h| h != reset && functions[h].start == v & !1) {
            handlers.entry(functions[h].name.clone()).or_insert_with(|| deepest(&functions, &graph.frames, &succ, h));
        }
    }
    let handlers: Vec<(String, StackPath)> = handlers.into_iter().collect();
    let worst = thread.bytes + handlers.iter().map(|(_, p)| p.bytes + EXCEPTION_FRAME_BYTES).sum::<u32>();
    Ok(StackBound { thread, handlers, worst, stack, cycles: recursive_groups(&functions, &succ) })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A made-up image: `Reset` calls `a` (push 4 registers, sub 16: 32 bytes) which calls `b`
    /// (push 2 and vpush of 2 doubles and a 4 096-byte sub.w: 4 120 bytes) and tail-calls `c`
    /// (str with pre-decrement 4, sub 8: 12 bytes); `c` calls itself (recursion, cut); `d` is
    /// reached only indirectly from `c` through a literal pool word. The deepest path from
    /// Reset: Reset (8) + a (32) + b (4 120) = 4 160, hand-added; through `c` it would be
    /// 8 + 32 + 12 + d's 64 = 116.
    const NM: &str = "08000000 00000010 T Reset\n08000010 00000020 t a\n08000030 00000010 t b\n\
        08000040 00000020 t c\n08000060 00000008 t <d as e>::f\n20000100 B _stack_end\n20001000 A _stack_start\n";
    const DISASSEMBLY: &str = "
 8000000:      \tpush\t{r7, lr}
 8000002:      \tbl\t0x8000010 <a>           @ imm = #12
 8000010:      \tpush\t{r4, r5, r7, lr}
 8000012:      \tsub\tsp, #16
 8000014:      \tbl\t0x8000030 <b>
 8000018:      \tbne\t0x8000012 <a+0x2>
 800001a:      \tb.w\t0x8000040 <c>
 8000030:      \tpush.w\t{r8, r9}
 8000034:      \tvpush\t{d8, d9}
 8000038:      \tsub.w\tsp, sp, #4096
 8000040:      \tstr\tr11, [sp, #-4]!
 8000044:      \tsub\tsp, #8
 8000046:      \tbl\t0x8000040 <c>
 800004a:      \tldr\tr1, [pc, #4]
 800004c:      \tblx\tr1
 800004e:      \tbx\tlr
 8000050:\t61 00 00 08\t.word\t0x08000061
 8000060:      \tpush\t{r0, r1, r2, r3, r4, r5, r6, r7}
 8000062:      \tsub\tsp, #32
";

    #[test]
    fn frames_calls_and_the_deepest_path_of_a_made_up_image() {
        let f = functions(NM);
        assert_eq!(f.iter().map(|x| x.name.as_str()).collect::<Vec<_>>(), ["Reset", "a", "b", "c", "<d as e>::f"]);
        assert_eq!((symbol(NM, "_stack_start"), symbol(NM, "_stack_end")), (Some(0x2000_1000), Some(0x2000_0100)));
        let g = call_graph(&f, DISASSEMBLY, &[]).unwrap();
        assert_eq!(g.frames, [8, 32, 4_120, 12, 64]);
        assert_eq!(g.calls[1], BTreeSet::from([2, 3]), "a calls b and tail-calls c; its own loop is no call");
        assert_eq!(g.indirect, [false, false, false, true, false], "bx lr is a return, blx r1 a call");
        assert_eq!(g.address_taken, BTreeSet::from([4]));
        let succ = successors(&f, &g).unwrap();
        assert_eq!(succ[3], BTreeSet::from([3, 4]));
        let path = deepest(&f, &g.frames, &succ, 0);
        assert_eq!(path.bytes, 4_160);
        assert_eq!(path.functions.iter().map(|x| x.0.as_str()).collect::<Vec<_>>(), ["Reset", "a", "b"]);
        assert_eq!(deepest(&f, &g.frames, &succ, 3).bytes, 12 + 64, "c's recursion cut, d indirect");
        assert_eq!(recursive_groups(&f, &succ), vec![vec!["c".to_string()]]);
    }

    /// A write to sp the analysis cannot size fails it rather than reading as nothing.
    #[test]
    fn an_unknown_write_to_sp_fails_the_analysis() {
        let f = functions(NM);
        for bad in [" 8000012:      \tsub\tsp, r4", " 8000012:      \tmov\tsp, r7"] {
            let e = call_graph(&f, bad, &[]).unwrap_err().to_string();
            assert!(e.contains("write to sp"), "{e}");
        }
    }

    /// A task poll no executor runs fails the analysis.
    #[test]
    fn a_task_no_executor_runs_fails_the_analysis() {
        let nm = "08000000 00000010 T Reset\n08000010 00000010 t _TaskStorage_new_task_poll\n";
        let f = functions(nm);
        let g = call_graph(&f, "", &[0x0800_0011]).unwrap();
        let e = successors(&f, &g).unwrap_err().to_string();
        assert!(e.contains("runs in no executor"), "{e}");
    }
}
