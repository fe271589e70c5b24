//! Run a scenario on the FMU through the `fmi` crate (FMI 3.0 Co-Simulation import).

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};
use fmi::fmi3::import::Fmi3Import;
use fmi::fmi3::instance::InstanceCS;
use fmi::fmi3::{CoSimulation, Common, Fmi3Model, GetSet};
use fmi::schema::fmi3::{Causality, VariableType};
use fmi::traits::FmiImport;

use crate::fmu::scenario::{Scenario, Value};
use crate::fmu::trace::{Gather, Trace};

/// A variable of the model description.
#[derive(Clone, Debug)]
pub struct VariableInfo {
    pub name: String,
    pub vr: u32,
    pub kind: Kind,
    pub causality: Causality,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    Float64,
    Int32,
    Boolean,
}

/// Unpack an FMI 3.0 archive and read its model description with the `fmi` crate.
///
/// fmi-schema 0.8 reads `BaseUnit`'s ampere and kelvin exponents under the names `a` and `k`
/// and refuses the standard's `A` and `K` (strict attributes): the model description in the
/// unpacked copy gets its `BaseUnit` exponents renamed for it, nothing else changes. The
/// archive itself keeps the standard's spelling (fmpy validate, fmutool and the FMI 2.0 side
/// of the crate read it as the standard says).
pub fn import_fmi3(path: &Path) -> Result<Fmi3Import> {
    let file = std::fs::File::open(path)?;
    let mut archive = zip::ZipArchive::new(file)?;
    let dir = tempfile::Builder::new().prefix("servo-fmu").tempdir()?;
    archive.extract(dir.path())?;
    let xml =
        std::fs::read_to_string(dir.path().join("modelDescription.xml")).context("reading modelDescription.xml")?;
    match fmi_version(&xml) {
        Some(v) if v.starts_with("3.") => {}
        Some(v) => bail!(
            "it is an FMI {v} FMU; the host tools run FMI 3.0 FMUs: pass the FMI 3.0 archive (target/fmu/servo_axis.fmu; `cargo run -p xtask -- bundle` builds both, the FMI 2.0 one is for FMI 2.0 importers such as fmpy)"
        ),
        None => bail!("its modelDescription.xml names no fmiVersion: not an FMU the host tools can run (they run FMI 3.0 FMUs)"),
    }
    let patched = base_units_for_fmi_schema(&xml);
    Ok(<Fmi3Import as FmiImport>::new(dir, &patched)?)
}

/// The `fmiVersion` attribute of a model description's root element (FMI 2.0: "2.0", FMI 3.0:
/// "3.0"); the first occurrence of the attribute is the root's.
fn fmi_version(xml: &str) -> Option<&str> {
    let start = xml.find("fmiVersion")? + "fmiVersion".len();
    let rest = xml[start..].trim_start().strip_prefix('=')?.trim_start();
    let quote = rest.chars().next().filter(|c| *c == '"' || *c == '\'')?;
    let value = &rest[1..];
    value.find(quote).map(|end| &value[..end])
}

fn base_units_for_fmi_schema(xml: &str) -> String {
    let mut out = String::with_capacity(xml.len());
    let mut rest = xml;
    while let Some(i) = rest.find("<BaseUnit") {
        let end = i + rest[i..].find('>').unwrap_or(rest.len() - i);
        out.push_str(&rest[..i]);
        out.push_str(&rest[i..end].replace(" A=\"", " a=\"").replace(" K=\"", " k=\""));
        rest = &rest[end..];
    }
    out.push_str(rest);
    out
}

/// [`Fmu::as_drive_twin`]'s and [`Fmu::as_twin_of`]'s guard: the FMU's runs are a drive's
/// twin until it is dropped (the twin before it restored).
pub struct DriveTwin<'a>(&'a Fmu, Option<TwinParameters>);

impl std::ops::Deref for DriveTwin<'_> {
    type Target = Fmu;
    fn deref(&self) -> &Fmu {
        self.0
    }
}

impl Drop for DriveTwin<'_> {
    fn drop(&mut self) {
        *self.0.drive_twin.borrow_mut() = self.1.take();
    }
}

/// The parameters a drive's commissioning owns: its motor model, its current loop's gains and
/// whether the loop feeds the back-EMF forward. An experiment on a drive cannot set them (the
/// drive keeps its own, its twin takes the drive's); [`refuse_drive_owned`] says so before
/// anything runs.
pub const DRIVE_OWNED: [&str; 8] = [
    "ctrl.motor_pole_pairs",
    "ctrl.motor_resistance",
    "ctrl.motor_ld",
    "ctrl.motor_lq",
    "ctrl.motor_flux_linkage",
    "ctrl.current_kp",
    "ctrl.current_ki",
    "ctrl.decoupling",
];

/// An experiment on a drive that sets one of [`DRIVE_OWNED`]: refused by name.
pub fn refuse_drive_owned<'a>(names: impl IntoIterator<Item = &'a String>) -> Result<()> {
    if let Some(name) = names.into_iter().find(|n| DRIVE_OWNED.contains(&n.as_str())) {
        bail!(
            "{name} is the drive's: with --device the drive runs, and its twin takes, the motor, the current-loop \
             gains and the back-EMF feed-forward's choice its commissioning measured, designed and made (`servo \
             commission --device PORT` decides them again, with --bandwidth for other gains), so it cannot be set \
             for one experiment"
        );
    }
    Ok(())
}

/// The parameters a twin's runs take in place of the FMU's: `commissioning.at_start` off, and
/// the motor, current-loop gains and feed-forward's choice of the drive it is the twin of.
type TwinParameters = Vec<(&'static str, Value)>;

/// A twin's parameters: a drive commissioned already (no commissioning at initialisation,
/// the plant's true mounting), with `drive`'s motor and current-loop gains where given.
/// A run that commissions at initialisation and applies the measured motor and current loop.
fn measures_own_motor(parameters: &BTreeMap<String, Value>) -> bool {
    use servo_axis::variables::name;
    let on = |n: &str| parameters.get(n) == Some(&Value::Bool(true));
    on(name::commissioning_at_start) && on(name::commissioning_apply_motor)
}

/// The drive's motor model, current-loop gains and feed-forward's choice among a twin's
/// parameters.
fn drive_motor_or_current_loop(name: &str) -> bool {
    name.starts_with("ctrl.motor_")
        || name == "ctrl.current_kp"
        || name == "ctrl.current_ki"
        || name == "ctrl.decoupling"
}

fn twin_parameters(drive: Option<&control_core::Params>) -> TwinParameters {
    use servo_axis::variables::name;
    let mut p = vec![(name::commissioning_at_start, Value::Bool(false))];
    if let Some(d) = drive {
        let m = &d.motor;
        p.extend([
            (name::ctrl_motor_pole_pairs, Value::Int(m.pole_pairs as i64)),
            (name::ctrl_motor_resistance, Value::Float(m.resistance as f64)),
            (name::ctrl_motor_ld, Value::Float(m.ld as f64)),
            (name::ctrl_motor_lq, Value::Float(m.lq as f64)),
            (name::ctrl_motor_flux_linkage, Value::Float(m.flux_linkage as f64)),
            (name::ctrl_current_kp, Value::Float(d.current.kp as f64)),
            (name::ctrl_current_ki, Value::Float(d.current.ki as f64)),
            (name::ctrl_decoupling, Value::Bool(d.current.decoupling)),
        ]);
    }
    p
}

/// A loaded FMU (unpacked once, instantiated per run).
pub struct Fmu {
    /// The FMU's library, opened once and held for the `Fmu`'s life: the `fmi` crate opens it
    /// again for every instance and closes it when the instance goes, so without this handle
    /// every run loaded the library anew (mapping, relocation, and the library's lazily
    /// computed statics such as its instantiation token: about 2 million instructions).
    /// Declared first: closed before `import` deletes the unpacked archive.
    _library: <Fmi3Import as FmiImport>::Binding,
    import: Fmi3Import,
    variables: BTreeMap<String, VariableInfo>,
    /// Runs are a drive's twin, with these parameters ([`Fmu::as_twin_of`]).
    drive_twin: std::cell::RefCell<Option<TwinParameters>>,
}

impl Fmu {
    pub fn load(path: &Path) -> Result<Self> {
        if !path.exists() {
            bail!(
                "FMU {} not found: build it with `cargo run -p xtask -- bundle` (or pass --fmu PATH)",
                path.display()
            );
        }
        let import = import_fmi3(path).map_err(|e| anyhow!("cannot import {}: {e}", path.display()))?;
        let mut variables = BTreeMap::new();
        for v in import.model_description().model_variables.iter_abstract() {
            let kind = match v.data_type() {
                VariableType::FmiFloat64 => Kind::Float64,
                VariableType::FmiInt32 => Kind::Int32,
                VariableType::FmiBoolean => Kind::Boolean,
                _ => continue,
            };
            variables.insert(
                v.name().to_string(),
                VariableInfo { name: v.name().to_string(), vr: v.value_reference(), kind, causality: v.causality() },
            );
        }
        let model_identifier = import
            .model_description()
            .co_simulation
            .as_ref()
            .map(|cs| cs.model_identifier.clone())
            .ok_or_else(|| anyhow!("{} is not a co-simulation FMU", path.display()))?;
        let library = import
            .binding(&model_identifier)
            .map_err(|e| anyhow!("cannot load the library of {}: {e}", path.display()))?;
        Ok(Self { _library: library, import, variables, drive_twin: std::cell::RefCell::new(None) })
    }

    pub fn variable(&self, name: &str) -> Result<&VariableInfo> {
        self.variables.get(name).ok_or_else(|| {
            let close: Vec<&str> = self
                .variables
                .keys()
                .filter(|k| k.contains(name) || name.contains(k.as_str()))
                .map(String::as_str)
                .take(5)
                .collect();
            anyhow!(
                "the FMU has no variable `{name}`{}",
                if close.is_empty() { String::new() } else { format!(" (did you mean {close:?}?)") }
            )
        })
    }

    /// All outputs, in model-description order of value reference.
    pub fn outputs(&self) -> Vec<&VariableInfo> {
        let mut v: Vec<&VariableInfo> = self.variables.values().filter(|v| v.causality == Causality::Output).collect();
        v.sort_by_key(|v| v.vr);
        v
    }

    fn set(inst: &mut InstanceCS, var: &VariableInfo, value: Value) -> Result<()> {
        let r = match (var.kind, value) {
            (Kind::Float64, v) => inst.set_float64(&[var.vr], &[v.as_f64()]),
            (Kind::Int32, Value::Int(i)) => {
                let i = i32::try_from(i).map_err(|_| anyhow!("{} = {i} does not fit a 32-bit integer", var.name))?;
                inst.set_int32(&[var.vr], &[i])
            }
            // Model files keep every parameter as a number: a whole one sets an integer.
            (Kind::Int32, Value::Float(f)) if f.fract() == 0.0 && f >= i32::MIN as f64 && f <= i32::MAX as f64 => {
                inst.set_int32(&[var.vr], &[f as i32])
            }
            (Kind::Boolean, Value::Bool(b)) => inst.set_boolean(&[var.vr], &[b]),
            (kind, v) => bail!("{} is {kind:?}; {v:?} is not a value of that type", var.name),
        };
        r.map(|_| ()).map_err(|_| anyhow!("the FMU refused {} = {value}: {}", var.name, crate::fmu::log::reasons()))
    }

    /// The outputs `names` (the scenario's `record` list, in its order), or every output when
    /// it is empty: the Float64 outputs, then the Int32 ones, then the Boolean ones, each in
    /// value-reference order, the order a step reads them in (one Get per type), so that a
    /// recorded row is the values as read, without a gather into another order.
    pub fn recorded(&self, names: &[String]) -> Result<Vec<&VariableInfo>> {
        if names.is_empty() {
            let mut outputs = self.outputs();
            outputs.sort_by_key(|v| (kind_rank(v.kind), v.vr));
            return Ok(outputs);
        }
        names
            .iter()
            .map(|n| {
                let var = self.variable(n)?;
                if var.causality != Causality::Output {
                    bail!("record lists `{n}`, which is not an output of the FMU (it is {:?})", var.causality);
                }
                Ok(var)
            })
            .collect()
    }

    /// Run `scenario`; `progress` is called with the fraction done.
    /// This FMU as the twin of a drive that is already commissioned, for as long as the
    /// returned guard lives: `commissioning.at_start` off unless a scenario sets it, so the
    /// twin's drive starts with the plant's own motor and mounting at time 0, as the drive
    /// starts with the set it measured (the FMU's default commissions at initialisation, as a
    /// drive at power-up, and its time 0 would then be where that left the axis). For runs
    /// planned before a drive is at hand; [`Fmu::as_twin_of`] once it is.
    pub fn as_drive_twin(&self) -> DriveTwin<'_> {
        let before = self.drive_twin.replace(Some(twin_parameters(None)));
        DriveTwin(self, before)
    }

    /// This FMU as the twin of the drive whose parameters are `drive` (read from it), for as
    /// long as the returned guard lives: as [`Fmu::as_drive_twin`], and the twin's drive runs
    /// with `drive`'s commissioned motor, current-loop gains and feed-forward's choice (what the drive runs every
    /// experiment with), not with the plant's truth. A drive that is not commissioned has no
    /// such set: refused, saying what to do.
    pub fn as_twin_of(&self, drive: &control_core::Params) -> Result<DriveTwin<'_>> {
        if !drive.commissioned {
            bail!(
                "the drive's motor is not commissioned: run `servo commission --device PORT` first (it measures the \
                 motor and the encoder's mounting; --save keeps them in the drive's flash)"
            );
        }
        let before = self.drive_twin.replace(Some(twin_parameters(Some(drive))));
        Ok(DriveTwin(self, before))
    }

    /// The parameters this FMU's runs take in place of a scenario's while it is a drive's twin
    /// (none otherwise): what plans of a twin's run (its torque and current ceilings) build
    /// the twin's drive from, as the run does.
    pub fn twin_parameters(&self) -> BTreeMap<String, Value> {
        self.twin_parameters_for(&BTreeMap::new())
    }

    /// [`Self::twin_parameters`] for a run of `parameters`: a run that commissions its twin at
    /// initialisation and applies what it measured (`commissioning.at_start` and
    /// `commissioning.apply_motor`) measures the twin's motor and current loop itself and is
    /// not given the drive's; one that commissions only the mounting runs the drive's.
    pub fn twin_parameters_for(&self, parameters: &BTreeMap<String, Value>) -> BTreeMap<String, Value> {
        let measures_motor = measures_own_motor(parameters);
        self.drive_twin
            .borrow()
            .as_ref()
            .map(|twin| {
                twin.iter()
                    .filter(|(name, _)| !(measures_motor && drive_motor_or_current_loop(name)))
                    .map(|&(name, value)| (name.to_string(), value))
                    .collect()
            })
            .unwrap_or_default()
    }

    pub fn run(&self, scenario: &Scenario, progress: impl FnMut(f64)) -> Result<Trace> {
        self.run_until(scenario, progress, |_| false)
    }

    /// Run `scenario` until its stop time or until `done` says so of a recorded row (time,
    /// then the recorded outputs in trace order); the trace ends with that row.
    pub fn run_until(
        &self,
        scenario: &Scenario,
        progress: impl FnMut(f64),
        done: impl FnMut(&[f64]) -> bool,
    ) -> Result<Trace> {
        self.run_inner(scenario, progress, done, true)
    }

    /// Run `scenario` reading every recorded output at every step but keeping only the last
    /// row (what the FMI boundary costs without the memory a trace takes; `servo bench fmu`).
    pub fn run_reading_only(&self, scenario: &Scenario) -> Result<Trace> {
        self.run_inner(scenario, |_| {}, |_| false, false)
    }

    fn run_inner(
        &self,
        scenario: &Scenario,
        mut progress: impl FnMut(f64),
        mut done: impl FnMut(&[f64]) -> bool,
        keep_rows: bool,
    ) -> Result<Trace> {
        let mut params: Vec<(&VariableInfo, Value)> = scenario
            .parameters
            .iter()
            .map(|(n, v)| {
                let var = self.variable(n)?;
                if var.causality != Causality::Parameter {
                    bail!("`{n}` is not a parameter of the FMU (it is {:?})", var.causality);
                }
                Ok((var, *v))
            })
            .collect::<Result<_>>()?;
        if let Some(twin) = self.drive_twin.borrow().as_ref() {
            // A scenario that commissions its twin at initialisation and applies what it
            // measured measures the twin's motor and current loop itself: the drive's are not
            // given to it (one that commissions the mounting only runs the drive's motor).
            let measures_motor = measures_own_motor(&scenario.parameters);
            for &(name, value) in twin {
                let given = scenario.parameters.contains_key(name);
                if measures_motor && drive_motor_or_current_loop(name) {
                    continue;
                }
                if name == servo_axis::variables::name::commissioning_at_start {
                    if !given {
                        params.push((self.variable(name)?, value));
                    }
                } else if given {
                    refuse_drive_owned([&name.to_string()])?;
                } else {
                    params.push((self.variable(name)?, value));
                }
            }
        }
        // Inputs are set when they change, not at every step.
        let changes: Vec<(usize, Vec<(&VariableInfo, Value)>)> = scenario
            .changes()
            .into_iter()
            .map(|(k, group)| {
                let group = group
                    .into_iter()
                    .map(|(n, v)| {
                        let var = self.variable(n)?;
                        if var.causality != Causality::Input {
                            bail!("event sets `{n}`, which is not an input of the FMU (it is {:?})", var.causality);
                        }
                        Ok((var, v))
                    })
                    .collect::<Result<Vec<_>>>()?;
                Ok((k, group))
            })
            .collect::<Result<_>>()?;
        let outputs = self.recorded(&scenario.record)?;

        crate::fmu::log::install();
        crate::fmu::log::clear();
        let mut inst = self
            .import
            .instantiate_cs(&scenario.name, false, false, false, false, &[])
            .map_err(|e| anyhow!("cannot instantiate the FMU: {e}"))?;
        for (var, v) in &params {
            Self::set(&mut inst, var, *v)?;
        }
        let h = scenario.step();
        let n = scenario.steps();
        inst.enter_initialization_mode(None, 0.0, Some(scenario.stop_time))
            .map_err(|_| anyhow!("enter initialization mode failed: {}", crate::fmu::log::reasons()))?;
        let mut pending = changes.iter().peekable();
        let mut apply = |inst: &mut InstanceCS, k: usize| -> Result<()> {
            while let Some((_, group)) = pending.next_if(|(j, _)| *j <= k) {
                for (var, v) in group {
                    Self::set(inst, var, *v)?;
                }
            }
            Ok(())
        };
        apply(&mut inst, 0)?;
        inst.exit_initialization_mode()
            .map_err(|_| anyhow!("the FMU refused its parameters at initialization: {}", crate::fmu::log::reasons()))?;

        let mut columns = vec!["time".to_string()];
        columns.extend(outputs.iter().map(|v| v.name.clone()));
        let mut trace = Trace::new(columns);
        // Reserved up to the trace budget: a scenario built in code (a sweep's longest
        // schedule, say, which `run_until` usually ends early) cannot abort on an allocation
        // of memory its run never fills; files are refused beyond it when loaded.
        let budget_rows = (crate::fmu::trace_budget::MAX_TRACE_BYTES / (8.0 * (outputs.len() + 1) as f64)) as usize;
        trace.rows.reserve_exact(if keep_rows { (n + 1).min(budget_rows) } else { 1 });
        // Outputs are read in one call per type into one buffer, `[time, Float64 outputs,
        // Int32 outputs, Boolean outputs]`, then copied into the row in column order.
        let of_kind = |kind: Kind| -> (Vec<usize>, Vec<u32>) {
            outputs.iter().enumerate().filter(|(_, v)| v.kind == kind).map(|(i, v)| (i, v.vr)).unzip()
        };
        let (f64_cols, f64_vrs) = of_kind(Kind::Float64);
        let (i32_cols, i32_vrs) = of_kind(Kind::Int32);
        let (bool_cols, bool_vrs) = of_kind(Kind::Boolean);
        // The buffer index of each column (column 0 is the time, buffer index 0).
        let mut sources = vec![0; outputs.len() + 1];
        for (k, &c) in f64_cols.iter().chain(&i32_cols).chain(&bool_cols).enumerate() {
            sources[c + 1] = k + 1;
        }
        let gather = Gather::new(sources, outputs.len() + 1);
        let (f64_end, i32_end) = (1 + f64_vrs.len(), 1 + f64_vrs.len() + i32_vrs.len());
        let mut buffer = vec![0.0; outputs.len() + 1];
        let (mut i32_buf, mut bool_buf) = (vec![0; i32_vrs.len()], vec![false; bool_vrs.len()]);
        let mut record = |inst: &mut InstanceCS, t: f64, trace: &mut Trace| -> Result<()> {
            buffer[0] = t;
            if !f64_vrs.is_empty() {
                inst.get_float64(&f64_vrs, &mut buffer[1..f64_end]).map_err(|e| anyhow!("get outputs: {e:?}"))?;
            }
            if !i32_vrs.is_empty() {
                inst.get_int32(&i32_vrs, &mut i32_buf).map_err(|e| anyhow!("get outputs: {e:?}"))?;
                for (b, &v) in buffer[f64_end..i32_end].iter_mut().zip(&i32_buf) {
                    *b = v as f64;
                }
            }
            if !bool_vrs.is_empty() {
                inst.get_boolean(&bool_vrs, &mut bool_buf).map_err(|e| anyhow!("get outputs: {e:?}"))?;
                for (b, &v) in buffer[i32_end..].iter_mut().zip(&bool_buf) {
                    *b = v as i32 as f64;
                }
            }
            if !keep_rows {
                trace.rows.clear();
            }
            trace.rows.push_gathered(&buffer, &gather);
            Ok(())
        };
        record(&mut inst, 0.0, &mut trace)?;
        let (mut ev, mut term, mut early, mut last) = (false, false, false, 0.0);
        for k in 0..n {
            let t = k as f64 * h;
            apply(&mut inst, k)?;
            inst.do_step(t, h, true, &mut ev, &mut term, &mut early, &mut last)
                .map_err(|_| anyhow!("do_step at t = {t} s failed: {}", crate::fmu::log::reasons()))?;
            record(&mut inst, (k + 1) as f64 * h, &mut trace)?;
            if k % 256 == 0 {
                progress(k as f64 / n as f64);
            }
            if trace.rows.last().is_some_and(&mut done) {
                break;
            }
        }
        progress(1.0);
        inst.terminate().ok();
        Ok(trace)
    }
}

/// The order the step's Gets read the output types in (Float64, Int32, Boolean).
fn kind_rank(kind: Kind) -> u8 {
    match kind {
        Kind::Float64 => 0,
        Kind::Int32 => 1,
        Kind::Boolean => 2,
    }
}

/// Result of one check of a scenario.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CheckResult {
    pub signal: String,
    pub description: String,
    pub passed: bool,
    /// Smallest and largest value of the signal in the window.
    pub observed: (f64, f64),
    pub min: Option<f64>,
    pub max: Option<f64>,
    pub window: (f64, f64),
    /// Why the check was not evaluated (a window the trace does not cover): it then fails.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub not_evaluated: Option<String>,
}

pub fn evaluate_checks(scenario: &Scenario, trace: &Trace) -> Result<Vec<CheckResult>> {
    let time = trace.column("time").context("trace has no time column")?;
    let mut results = Vec::new();
    for c in &scenario.checks {
        let values =
            trace.column(&c.signal).with_context(|| format!("check: no signal `{}` in the result", c.signal))?;
        let (from, to) = match c.at {
            Some(at) => (at, at),
            None => (c.from.unwrap_or(0.0), c.to.unwrap_or(scenario.stop_time)),
        };
        let h = scenario.step();
        let mut result = CheckResult {
            signal: c.signal.clone(),
            description: c.description.clone().unwrap_or_default(),
            passed: false,
            observed: (f64::NAN, f64::NAN),
            min: c.min,
            max: c.max,
            window: (from, to),
            not_evaluated: None,
        };
        // Judged only where the trace has samples: a window that ends past its end, or before
        // its first sample, fails with the reason, never on the nearest sample. (A window from
        // 0 on a drive's telemetry, whose first sample comes one telemetry period after the
        // start, is judged on the samples it holds.)
        let (first, last) = (time.first().copied().unwrap_or(f64::NAN), time.last().copied().unwrap_or(f64::NAN));
        if !(to >= first - 0.5 * h && to <= last + 0.5 * h) {
            result.not_evaluated = Some(format!("the trace covers [{first}, {last}] s, not [{from}, {to}] s"));
            results.push(result);
            continue;
        }
        let mut idx: Vec<usize> =
            (0..time.len()).filter(|&i| time[i] >= from - 0.5 * h && time[i] <= to + 0.5 * h).collect();
        if idx.is_empty() && c.at.is_some() {
            // A trace sampled off the step grid (a drive's telemetry): the value in force at
            // that time is the latest sample before it (one exists: `at` is inside the trace).
            idx.extend(time.iter().rposition(|&t| t <= to + 0.5 * h));
        }
        if idx.is_empty() {
            bail!("check on {}: no sample in [{from}, {to}] s", c.signal);
        }
        let lo = c.min.unwrap_or(f64::NEG_INFINITY);
        let hi = c.max.unwrap_or(f64::INFINITY);
        result.observed =
            idx.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &i| (a.min(values[i]), b.max(values[i])));
        result.passed = idx.iter().all(|&i| values[i] >= lo && values[i] <= hi);
        results.push(result);
    }
    Ok(results)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fmu::scenario::Check;

    /// A drive's telemetry: samples every 0.7 ms (off the 0.25 ms grid) from sample `first`
    /// (at `first`·0.7 ms) to 0.3010 s, the value equal to the sample's time.
    fn drive_trace(first: usize) -> Trace {
        let mut t = Trace::new(vec!["time".into(), "iq".into()]);
        for k in first..=430 {
            let time = k as f64 * 0.7e-3;
            t.rows.push([time, time]);
        }
        t
    }

    /// A check that `iq` stays at most 1 at `at` or over `window`.
    fn iq_check(at: Option<f64>, window: Option<(f64, f64)>) -> Check {
        Check {
            signal: "iq".into(),
            at,
            from: window.map(|w| w.0),
            to: window.map(|w| w.1),
            min: None,
            max: Some(1.0),
            description: None,
        }
    }

    fn check(at: Option<f64>, window: Option<(f64, f64)>) -> CheckResult {
        let s = Scenario { checks: vec![iq_check(at, window)], ..scenario() };
        evaluate_checks(&s, &drive_trace(0)).unwrap().remove(0)
    }

    fn scenario() -> Scenario {
        Scenario {
            name: "x".into(),
            description: String::new(),
            stop_time: 0.3,
            step: None,
            parameters: Default::default(),
            events: vec![],
            checks: vec![],
            plot: vec![],
            record: vec![],
        }
    }

    #[test]
    fn a_check_off_the_sample_grid_takes_the_sample_in_force_but_never_one_past_the_trace() {
        // 0.2999 s is more than half a step from every sample (0.2996 and 0.3003 s are the
        // nearest): the value in force is the latest sample before it.
        let r = check(Some(0.2999), None);
        assert!(r.passed && r.not_evaluated.is_none(), "{r:?}");
        assert_eq!(r.observed.0, 428.0 * 0.7e-3);
        // Past the trace's end: not judged on its last sample.
        let r = check(Some(7.0), None);
        assert!(!r.passed && r.not_evaluated.as_deref().is_some_and(|w| w.contains("not [7, 7] s")), "{r:?}");
        let r = check(None, Some((0.1, 0.5)));
        assert!(!r.passed && r.not_evaluated.is_some(), "{r:?}");
        let r = check(None, Some((0.1, 0.3)));
        assert!(r.passed && r.not_evaluated.is_none(), "{r:?}");
        // A drive's first sample comes after the start: a window from 0 is judged on the
        // samples it holds; a moment before the first sample is not evaluated.
        let trace = drive_trace(3);
        let s =
            |at: Option<f64>, window: Option<(f64, f64)>| Scenario { checks: vec![iq_check(at, window)], ..scenario() };
        let r = evaluate_checks(&s(None, Some((0.0, 0.3))), &trace).unwrap().remove(0);
        assert!(r.passed && r.observed.0 == 3.0 * 0.7e-3, "{r:?}");
        let r = evaluate_checks(&s(Some(0.001), None), &trace).unwrap().remove(0);
        assert!(!r.passed && r.not_evaluated.is_some(), "{r:?}");
    }

    #[test]
    fn the_fmi_version_is_read_from_the_root_element() {
        assert_eq!(fmi_version(r#"<?xml version="1.0"?><fmiModelDescription fmiVersion="2.0" guid="x">"#), Some("2.0"));
        assert_eq!(fmi_version("<fmiModelDescription fmiVersion = '3.0' instantiationToken='t'>"), Some("3.0"));
        assert_eq!(fmi_version("<fmiModelDescription modelName='m'>"), None);
    }
}
