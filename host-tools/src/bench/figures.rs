//! The figures every `servo bench …` writes beside its console output, in one shape: per
//! figure its name, goal, measured worst case, unit, whether the goal is met and the command
//! that printed it, stamped with the commit, the date (UTC) and the machine. One file per
//! bench, `out/bench/<bench>.json` (`<--out>/<bench>.json` with --out); `servo figures` renders
//! them into the book's figures page and `servo index` into the report.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};

/// What marks a file as a bench's figures (out/bench/ also holds other JSON files).
pub const FORMAT: &str = "servo-bench-figures/1";

/// One bench run's figures.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct BenchFigures {
    pub format: String,
    /// The file's name without `.json`: the bench, with its variant (`accdec-random`).
    pub bench: String,
    /// The command line that printed the figures (`servo bench …`).
    pub command: String,
    /// Every goal met and every check passed (the bench's exit status 0).
    pub passed: bool,
    pub stamp: Stamp,
    pub figures: Vec<Figure>,
}

/// One figure: the worst case measured over the bench's range, against its goal.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Figure {
    pub name: String,
    /// None: a figure printed for information, without a goal.
    pub goal: Option<Goal>,
    /// The worst case (the largest error, the smallest margin).
    pub measured: f64,
    pub unit: String,
    /// None when the figure has no goal.
    pub met: Option<bool>,
    /// The command that printed it.
    pub command: String,
}

/// A goal: the measured value at most, at least or equal to `value`.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct Goal {
    pub bound: Bound,
    pub value: f64,
}

#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum Bound {
    AtMost,
    AtLeast,
    Equal,
}

impl Goal {
    pub fn met_by(&self, measured: f64) -> bool {
        match self.bound {
            Bound::AtMost => measured <= self.value,
            Bound::AtLeast => measured >= self.value,
            Bound::Equal => measured == self.value,
        }
    }

    /// `≤ 0.1 dB`, `≥ 400×`, `0`.
    pub fn text(&self, unit: &str) -> String {
        let sign = match self.bound {
            Bound::AtMost => "≤ ",
            Bound::AtLeast => "≥ ",
            Bound::Equal => "",
        };
        format!("{sign}{}", with_unit(self.value, unit))
    }
}

impl Figure {
    /// `0.078 dB`, `300×`, `0`.
    pub fn measured_text(&self) -> String {
        with_unit(self.measured, &self.unit)
    }

    pub fn goal_text(&self) -> String {
        self.goal.map_or(String::new(), |g| g.text(&self.unit))
    }

    /// A goal that is there and not met.
    pub fn not_met(&self) -> bool {
        self.met == Some(false)
    }
}

/// Where and when the figures were measured.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, Eq)]
pub struct Stamp {
    /// The checked-out commit (short hash), `+changes` when the working tree differs from it;
    /// `unknown` outside a git checkout.
    pub commit: String,
    /// `YYYY-MM-DD HH:MM UTC`.
    pub date: String,
    pub machine: Machine,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, Eq)]
pub struct Machine {
    pub hostname: String,
    pub cpu: String,
    pub cores: usize,
}

impl Stamp {
    /// This checkout, now, this machine.
    pub fn now() -> Stamp {
        let secs = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs());
        Stamp { commit: commit(), date: utc_date(secs), machine: Machine::this() }
    }

    /// The stamp of this run: the checkout and time when the process took its first stamp
    /// (`servo` takes it before it runs anything), so a long bench's figures name the code
    /// that ran, not a commit made while it ran.
    pub fn of_this_run() -> Stamp {
        static RUN: std::sync::OnceLock<Stamp> = std::sync::OnceLock::new();
        RUN.get_or_init(Stamp::now).clone()
    }

    /// One line: `commit eae9d1a, 2025-06-01 10:00 UTC, vm (AMD EPYC, 2 cores)`.
    pub fn text(&self) -> String {
        format!(
            "commit `{}`, {}, {} ({}, {} core{})",
            self.commit,
            self.date,
            self.machine.hostname,
            self.machine.cpu,
            self.machine.cores,
            if self.machine.cores == 1 { "" } else { "s" }
        )
    }
}

impl Machine {
    pub fn this() -> Machine {
        let hostname = std::fs::read_to_string("/proc/sys/kernel/hostname")
            .ok()
            .or_else(|| std::env::var("HOSTNAME").ok())
            .or_else(|| std::env::var("COMPUTERNAME").ok())
            .map(|s| s.trim().to_string())
            .filter(|s| !s.is_empty())
            .unwrap_or_else(|| "unknown".into());
        let cpu = std::fs::read_to_string("/proc/cpuinfo")
            .ok()
            .and_then(|info| {
                info.lines()
                    .find(|l| l.starts_with("model name"))
                    .and_then(|l| l.split_once(':'))
                    .map(|(_, v)| v.split_whitespace().collect::<Vec<_>>().join(" "))
            })
            .filter(|s| !s.is_empty())
            .unwrap_or_else(|| std::env::consts::ARCH.to_string());
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        Machine { hostname, cpu, cores }
    }
}

/// The checkout's commit, `+changes` when its tracked files differ from it: the current
/// directory's (where the benches run, the workspace), else the workspace `servo` was built in.
fn commit() -> String {
    let here = std::process::Command::new("git").args(["rev-parse", "--is-inside-work-tree"]).output();
    let root = if here.is_ok_and(|o| o.status.success()) { PathBuf::from(".") } else { crate::paths::workspace_root() };
    let git = |args: &[&str]| {
        std::process::Command::new("git")
            .current_dir(&root)
            .args(args)
            .output()
            .ok()
            .filter(|o| o.status.success())
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
    };
    match git(&["rev-parse", "--short", "HEAD"]) {
        Some(hash) if !hash.is_empty() => {
            let changed = git(&["status", "--porcelain", "--untracked-files=no"]).is_some_and(|s| !s.is_empty());
            if changed {
                format!("{hash}+changes")
            } else {
                hash
            }
        }
        _ => "unknown".into(),
    }
}

/// Seconds since 1970 as `YYYY-MM-DD HH:MM UTC` (the civil calendar from the day count).
pub fn utc_date(secs: u64) -> String {
    let days = (secs / 86_400) as i64;
    let (hour, minute) = ((secs % 86_400) / 3600, (secs % 3600) / 60);
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!("{year:04}-{month:02}-{day:02} {hour:02}:{minute:02} UTC")
}

/// The command line that re-runs this bench: as typed, with `servo` for the binary's path and
/// without its output folder ([`rerun_command`]).
pub fn invoked_command() -> String {
    rerun_command(std::env::args().skip(1))
}

/// `servo` and `args`, less the output folder (`--out DIR` or `--out=DIR`: where the files
/// go, not what is measured, and often a scratch folder of the machine that ran it), quoted
/// where a word is empty or holds white space.
fn rerun_command(args: impl IntoIterator<Item = String>) -> String {
    let mut words = vec!["servo".to_string()];
    let mut args = args.into_iter();
    while let Some(a) = args.next() {
        if a == "--out" {
            args.next();
        } else if !a.starts_with("--out=") {
            words.push(if a.is_empty() || a.contains(char::is_whitespace) { format!("'{a}'") } else { a });
        }
    }
    words.join(" ")
}

/// A number for a table: about three significant digits, integers whole (grouped by
/// thousands), very small or very large ones as `2.1e-4`.
pub fn number(v: f64) -> String {
    if !v.is_finite() {
        return if v.is_nan() {
            "–".into()
        } else if v > 0.0 {
            "∞".into()
        } else {
            "−∞".into()
        };
    }
    if v == 0.0 {
        return "0".into();
    }
    let a = v.abs();
    let sign = if v < 0.0 { "−" } else { "" };
    if v.fract() == 0.0 && a < 1e12 {
        return format!("{sign}{}", grouped(a as u64));
    }
    if !(1e-3..1e7).contains(&a) {
        let s = format!("{a:.1e}");
        return format!("{sign}{s}");
    }
    let decimals = (2 - a.log10().floor() as i32).clamp(0, 6) as usize;
    let mut s = format!("{a:.decimals$}");
    if s.contains('.') {
        s = s.trim_end_matches('0').trim_end_matches('.').to_string();
    }
    if !s.contains('.') {
        if let Ok(n) = s.parse::<u64>() {
            s = grouped(n);
        }
    }
    format!("{sign}{s}")
}

fn grouped(n: u64) -> String {
    let digits = n.to_string();
    if digits.len() <= 4 {
        return digits;
    }
    let mut out = String::new();
    for (i, c) in digits.chars().enumerate() {
        if i > 0 && (digits.len() - i).is_multiple_of(3) {
            out.push(' ');
        }
        out.push(c);
    }
    out
}

/// `0.078 dB`, `0.87°`, `9.6 %`, `300×`.
pub fn with_unit(v: f64, unit: &str) -> String {
    match unit {
        "" => number(v),
        "°" | "×" => format!("{}{unit}", number(v)),
        _ => format!("{} {unit}", number(v)),
    }
}

/// A bench's figures as it measures them: `at_most`, `at_least`, `equal` and `info` add one
/// each; `write` stamps them and writes the file.
pub struct Recorder {
    figures: BenchFigures,
}

impl Recorder {
    /// `bench`: the file's name (the bench, with its variant when it measures something else).
    pub fn new(bench: &str) -> Recorder {
        let command = invoked_command();
        Recorder {
            figures: BenchFigures {
                format: FORMAT.into(),
                bench: bench.into(),
                command,
                passed: true,
                stamp: Stamp::of_this_run(),
                figures: Vec::new(),
            },
        }
    }

    /// The command that prints the figures, where it is not this process's `servo` command line
    /// (a test of `tests/` that records its figures): set before the first figure.
    pub fn command(&mut self, command: &str) -> &mut Self {
        self.figures.command = command.into();
        self
    }

    fn push(&mut self, name: &str, goal: Option<Goal>, measured: f64, unit: &str) -> &mut Self {
        let met = goal.map(|g| g.met_by(measured));
        let command = self.figures.command.clone();
        self.figures.figures.push(Figure { name: name.into(), goal, measured, unit: unit.into(), met, command });
        self
    }

    pub fn at_most(&mut self, name: &str, measured: f64, goal: f64, unit: &str) -> &mut Self {
        self.push(name, Some(Goal { bound: Bound::AtMost, value: goal }), measured, unit)
    }

    pub fn at_least(&mut self, name: &str, measured: f64, goal: f64, unit: &str) -> &mut Self {
        self.push(name, Some(Goal { bound: Bound::AtLeast, value: goal }), measured, unit)
    }

    pub fn equal(&mut self, name: &str, measured: f64, goal: f64, unit: &str) -> &mut Self {
        self.push(name, Some(Goal { bound: Bound::Equal, value: goal }), measured, unit)
    }

    /// A figure without a goal.
    pub fn info(&mut self, name: &str, measured: f64, unit: &str) -> &mut Self {
        self.push(name, None, measured, unit)
    }

    /// The last figure's verdict set by the bench (a goal its `Goal` cannot say, such as a
    /// check made on every row).
    pub fn verdict(&mut self, met: bool) -> &mut Self {
        if let Some(f) = self.figures.figures.last_mut() {
            f.met = Some(met);
        }
        self
    }

    /// Write `<dir>/<bench>.json`, `dir` being --out or `out/bench`; `passed` is the bench's
    /// verdict. Returns the file's path. The console says nothing: the bench's own output is
    /// unchanged.
    pub fn write(&mut self, out: Option<&Path>, passed: bool) -> Result<PathBuf> {
        self.figures.passed = passed;
        let dir = out.map(Path::to_path_buf).unwrap_or_else(|| crate::paths::default_out("bench"));
        write_figures(&dir, &self.figures)
    }

    pub fn figures(&self) -> &BenchFigures {
        &self.figures
    }

    /// No figure misses its goal.
    pub fn all_met(&self) -> bool {
        !self.figures.figures.iter().any(Figure::not_met)
    }

    /// The worst case on the console: `heading`, a line per figure against its goal (a missed
    /// one marked `NOT met`), the verdict.
    pub fn print_worst(&self, heading: &str) {
        println!("{heading}");
        for f in &self.figures.figures {
            let missed = if f.not_met() { "  NOT met" } else { "" };
            println!("  {:<40} {:>16}  goal {}{missed}", f.name, f.measured_text(), f.goal_text());
        }
        println!("{}", if self.all_met() { "every goal met" } else { "GOAL NOT MET" });
    }
}

/// Write `figures` as `<dir>/<bench>.json`.
pub fn write_figures(dir: &Path, figures: &BenchFigures) -> Result<PathBuf> {
    crate::paths::create_out_dir(dir)?;
    let path = dir.join(format!("{}.json", figures.bench));
    std::fs::write(&path, serde_json::to_string_pretty(figures)? + "\n")
        .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(path)
}

/// Every bench's figures in `dir` (files of another shape skipped), sorted by bench; a file
/// that says it holds figures but cannot be read is an error.
pub fn read_dir(dir: &Path) -> Result<Vec<BenchFigures>> {
    let mut all = Vec::new();
    for path in crate::page::files_with(dir, "json") {
        let text = std::fs::read_to_string(&path).with_context(|| format!("cannot read {}", path.display()))?;
        let Ok(value) = serde_json::from_str::<serde_json::Value>(&text) else { continue };
        if value.get("format").and_then(|f| f.as_str()) != Some(FORMAT) {
            continue;
        }
        let figures: BenchFigures = serde_json::from_value(value)
            .with_context(|| format!("{}: not a bench's figures in the format {FORMAT}", path.display()))?;
        all.push(figures);
    }
    all.sort_by(|a, b| a.bench.cmp(&b.bench));
    Ok(all)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The command shown beside the figures re-runs the bench: the output folder is left out,
    /// every other word kept in its order, quoted where it is empty or holds white space.
    #[test]
    fn the_rerun_command_leaves_out_the_output_folder() {
        let words = |s: &str| s.split(' ').map(String::from).collect::<Vec<_>>();
        assert_eq!(
            rerun_command(words("bench autotune --plants 200 --out /tmp/at/p200 --jobs 2")),
            "servo bench autotune --plants 200 --jobs 2"
        );
        assert_eq!(rerun_command(words("bench calibrate --out=/tmp/x --seed 3")), "servo bench calibrate --seed 3");
        assert_eq!(rerun_command(words("bench device --out")), "servo bench device");
        assert_eq!(
            rerun_command(["sweep".into(), "--set".into(), "a = 1".into(), "".into()]),
            "servo sweep --set 'a = 1' ''"
        );
    }

    #[test]
    fn dates_and_numbers() {
        assert_eq!(utc_date(0), "1970-01-01 00:00 UTC");
        assert_eq!(utc_date(951_782_400 + 3600 + 120), "2000-02-29 01:02 UTC");
        assert_eq!(utc_date(1_767_225_599), "2025-12-31 23:59 UTC");
        assert_eq!(number(0.078), "0.078");
        assert_eq!(number(9.912), "9.91");
        assert_eq!(number(125.1), "125");
        assert_eq!(number(13200.0), "13 200");
        assert_eq!(number(1_406_266.0), "1 406 266");
        assert_eq!(number(894.0), "894");
        assert_eq!(number(2.1e-4), "2.1e-4");
        assert_eq!(number(-0.0048), "−0.0048");
        assert_eq!(with_unit(0.87, "°"), "0.87°");
        assert_eq!(with_unit(300.0, "×"), "300×");
        let g = Goal { bound: Bound::AtMost, value: 0.1 };
        assert_eq!(g.text("dB"), "≤ 0.1 dB");
        assert!(g.met_by(0.1) && !g.met_by(0.11) && !g.met_by(f64::NAN));
    }
}
