#!/usr/bin/env python3
"""Other FMI importers on the servo FMU: each runs a scenario its own way and writes the CSV that
fmpy_run.py writes (same header, same float formatting), so the Rust tests compare it bit for bit
with the Rust host's trace. The scenario semantics are fmpy_run.py's (its helpers are reused):
parameters are start values; an event at time t sets inputs for the step that starts at t and
holds them; outputs are sampled after initialisation and after every step of `step` seconds
(0.00025 s unless the scenario says otherwise).

Usage:
  importers.py ecospy FMU SCENARIO.toml OUT.csv
      ecos (ecospy's C++ co-simulation engine, fmi4c underneath): FMI 3.0 only. The scenario's
      parameters and t = 0 inputs are set before init() (ecos applies them in initialisation
      mode), later inputs before the step they start; one step() per communication step.
      ecos ignores the status of doStep and of the other FMI calls, so its log (debug level: the
      FMU's messages with their status) is captured to OUT.csv.ecos.log and a Warning, Error or
      Fatal message from the FMU is reported; Error or Fatal fails the run.
  importers.py fmutool-check FMU
      `fmutool -input FMU -check` (fmu-manipulation-toolbox: the FMI XSD schema and the
      standard's semantic rules for the archive's FMI version). Fails on a non-zero exit, on any
      ERROR line, or when the tool does not say the FMU complies. Prints its report verbatim.
  importers.py fmutool-container FMU OUT.csv SCENARIO.toml
      Builds an FMU container (fmu-manipulation-toolbox) of the archive's FMI version around
      the FMU, exposing its inputs, outputs and parameters under their names (parameters as
      `<fmu>.<name>`), internal step = the scenario's step, build in debug mode (its log:
      OUT.csv.build.log); runs it with fmpy through the scenario with debug logging on (the
      container's loggingOn is handed to the embedded FMU, whose messages come back through the
      container's logger): every message goes to OUT.csv.container.log; an Error or Fatal
      message from the embedded FMU, or no message at all, fails the run.
  importers.py libcosim FMU SCENARIO.toml OUT.csv
      libcosim (the Open Simulation Platform's co-simulation library, through libcosimpy): FMI
      2.0 only (its FMI Library reads FMI 1.0 and 2.0; an FMI 3.0 archive is refused with
      libcosim's reason).
      The scenario's parameters and t = 0 inputs are initial values (applied in initialisation,
      which libcosim runs inside the first step), later inputs go through an override
      manipulator before the step they start; one step() per communication step, its time in
      integer nanoseconds. Outputs after each step from a last-value observer, those at t = 0
      from a time-series observer. libcosim reports a failed step as False (the FMU's message
      in its log at Warning level and up, on stdout), which fails the run.
Each command prints `<importer>: <seconds> s` (the run's wall time) on stderr.
"""
import ctypes
import faulthandler
import logging
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
import zipfile
import xml.etree.ElementTree as ET
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from fmpy_run import (  # noqa: E402  (the shared scenario helpers)
    INT_TYPES,
    REAL_TYPES,
    Scenario,
    output_names,
    scenario_inputs,
    simulate,
    write_csv,
)
from fmpy import read_model_description  # noqa: E402

STATUS = ["OK", "Warning", "Discard", "Error", "Fatal", "Pending"]


def fail(message):
    print(f"importers.py: {message}", file=sys.stderr)
    sys.exit(1)


def fmi_version(fmu):
    with zipfile.ZipFile(fmu) as z:
        return ET.fromstring(z.read("modelDescription.xml")).get("fmiVersion")


# ------------------------------------------------------------------------------------- ecospy
def run_ecospy(fmu, scenario, out):
    version = fmi_version(fmu)
    if version != "3.0":
        fail(f"ecospy runs FMI 3.0 here; {fmu} is FMI {version}")
    fmu = str(Path(fmu).resolve())
    sc = Scenario(scenario)
    md = read_model_description(fmu)
    variables, names, table = scenario_inputs(md, sc)
    out_names = output_names(md, sc)
    for nm in sc.parameters:
        if nm not in variables or variables[nm].causality != "parameter":
            fail(f"scenario parameter {nm!r} is not a parameter of the FMU")

    log_path = out + ".ecos.log"
    print(f"ecospy: the engine's log (and the FMU's messages) go to {log_path}", file=sys.stderr)
    # ecos (spdlog) and the FMU write to the process's stdout: send it to the log file.
    sys.stdout.flush()
    saved = os.dup(1)
    log_fd = os.open(log_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    os.dup2(log_fd, 1)
    os.close(log_fd)
    try:
        rows, wall = _ecospy_simulate(fmu, sc, variables, names, table, out_names)
    finally:
        sys.stdout.flush()
        ctypes.CDLL(None).fflush(None)  # the C side's buffered stdout, into the log file
        os.dup2(saved, 1)
        os.close(saved)

    # fmilibcpp logs each FMU message as "[<instance>] <status> <message>".
    text = Path(log_path).read_text(errors="replace")
    flagged = [ln for ln in text.splitlines() if re.search(r"\[servo\] (Warning|Discard|Error|Fatal|Unknown) ", ln)]
    for ln in flagged[:20]:
        print(f"ecospy log: {ln}", file=sys.stderr)
    write_csv(out, out_names, rows)
    print(f"ecospy: {wall:.3f} s", file=sys.stderr)
    if any(re.search(r"\[servo\] (Error|Fatal) ", ln) for ln in flagged):
        fail(f"the FMU logged an error under ecos (whole log: {log_path})")


def _ecospy_simulate(fmu, sc, variables, names, table, out_names):
    from ecospy import EcosLib, EcosSimulation, EcosSimulationStructure

    EcosLib.set_log_level("debug")
    inst = "servo"

    def ident(nm):
        return f"{inst}::{nm}"

    t0 = time.perf_counter()
    structure = EcosSimulationStructure()
    structure.add_model(inst, fmu)
    sim = EcosSimulation(structure=structure, step_size=sc.h)

    def setter(v):
        if v.type in INT_TYPES:
            return lambda x: sim.set_integer(ident(v.name), int(x))
        if v.type in REAL_TYPES:
            return lambda x: sim.set_real(ident(v.name), float(x))
        if v.type == "Boolean":
            return lambda x: sim.set_bool(ident(v.name), bool(x))
        fail(f"{v.name}: type {v.type} is not handled")

    def getter(v):
        if v.type in INT_TYPES:
            return lambda: sim.get_integer(ident(v.name))
        if v.type in REAL_TYPES:
            return lambda: sim.get_real(ident(v.name))
        if v.type == "Boolean":
            return lambda: sim.get_bool(ident(v.name))
        fail(f"{v.name}: type {v.type} is not handled")

    set_input = {nm: setter(variables[nm]) for nm in names}
    get_output = [getter(variables[nm]) for nm in out_names]

    def sample(t):
        return [t] + [g() for g in get_output]

    # Start values: the scenario's parameters and the inputs at t = 0, applied by ecos in
    # initialisation mode.
    for nm, value in sc.parameters.items():
        setter(variables[nm])(value)
    for nm in names:
        set_input[nm](table[0][nm])
    if not sim.init(0.0):
        fail(f"ecos init failed: {EcosLib.get_last_error()}")
    rows = [sample(0.0)]
    for k in range(sc.n):
        if k > 0:
            # Inputs that an event changed for the step starting at t_k (the others hold).
            for nm in names:
                if table[k][nm] != table[k - 1][nm]:
                    set_input[nm](table[k][nm])
        t_ecos = sim.step(1)
        t = (k + 1) * sc.h
        # ecos's clock is a running sum of h; the CSV's time column is the communication
        # point k*h, as the other runners write it.
        if abs(t_ecos - t) > 1e-9:
            fail(f"ecos is at t = {t_ecos} s after step {k + 1}, expected {t} s")
        rows.append(sample(t))
    sim.terminate()
    wall = time.perf_counter() - t0
    sim.free()
    structure.free()
    return rows, wall


# ------------------------------------------------------------------------------ fmutool check
def fmutool_command():
    exe = Path(sys.executable).parent / "fmutool"
    if exe.exists():
        return [str(exe)]
    return [sys.executable, "-m", "fmu_manipulation_toolbox.cli.fmutool"]


ANSI = re.compile(r"\x1b\[[0-9;]*m")


def run_fmutool_check(fmu):
    version = fmi_version(fmu)
    t0 = time.perf_counter()
    p = subprocess.run(fmutool_command() + ["-input", str(fmu), "-check"], capture_output=True, text=True)
    wall = time.perf_counter() - t0
    lines = [ANSI.sub("", ln).rstrip() for ln in (p.stdout + p.stderr).splitlines()]
    for ln in lines:
        print(ln)
    errors = [ln for ln in lines if ln.startswith(("ERROR", "CRITICAL"))]
    warnings = [ln for ln in lines if ln.startswith("WARNING")]
    print(f"fmutool-check: {wall:.3f} s", file=sys.stderr)
    print(f"fmutool-check: FMI {version}, exit {p.returncode}, {len(errors)} error(s), {len(warnings)} warning(s)")
    compliant = f"This FMU seems to be compliant with FMI-{version}."
    semantic = f"No semantic error against the FMI-{version[0]} standard."
    problems = []
    if p.returncode != 0:
        problems.append(f"fmutool exited with {p.returncode}")
    if errors:
        problems.append(f"{len(errors)} ERROR line(s)")
    for want in (compliant, semantic):
        if not any(want in ln for ln in lines):
            problems.append(f"no `{want}` in its report")
    if problems:
        fail(f"fmutool -check on {fmu} (FMI {version}): " + "; ".join(problems))


# -------------------------------------------------------------------------- fmutool container
def build_container(fmu, work, h, build_log):
    """The container FMU (same FMI version as `fmu`) around a copy of `fmu` in `work`."""
    from fmu_manipulation_toolbox.assembly import AssemblyNode

    version = int(fmi_version(fmu)[0])
    name = Path(fmu).name
    shutil.copy(fmu, work / name)
    log = logging.getLogger("fmu_manipulation_toolbox")
    handler = logging.FileHandler(build_log, mode="w")
    handler.setFormatter(logging.Formatter("%(levelname)-8s | %(message)s"))
    log.addHandler(handler)
    log.setLevel(logging.DEBUG)
    try:
        node = AssemblyNode("servo_container.fmu", step_size=h, auto_link=False, auto_input=True,
                            auto_output=True, auto_parameter=True)
        node.add_fmu(name)
        node.make_fmu(work, debug=True, fmi_version=version)
    finally:
        log.removeHandler(handler)
        handler.close()
    return work / "servo_container.fmu", Path(name).stem.lower(), version


class LogCollector:
    """The container's log messages (it forwards the embedded FMU's, prefixed with its name),
    each written to `path` as it comes (so a crash leaves the messages before it)."""

    def __init__(self, version, path):
        self.messages = []
        self.file = open(path, "w")

        def keep(status, category, message):
            self.messages.append((status, _text(category), _text(message)))
            label = STATUS[status] if 0 <= status < len(STATUS) else status
            self.file.write(f"[{label}] [{_text(category)}] {_text(message)}\n")
            self.file.flush()

        if version == 2:
            self.callback = lambda env, instance, status, category, message: keep(status, category, message)
        else:
            self.callback = lambda env, status, category, message: keep(status, category, message)


def _text(b):
    return b.decode("utf-8", "replace") if isinstance(b, bytes) else str(b)


def run_fmutool_container(fmu, out, scenario):
    sc = Scenario(scenario)
    md = read_model_description(fmu)
    out_names = output_names(md, sc)
    with tempfile.TemporaryDirectory(prefix="servo-container-") as tmp:
        work = Path(tmp)
        t0 = time.perf_counter()
        container, fmu_id, version = build_container(Path(fmu).resolve(), work, sc.h, out + ".build.log")
        build_wall = time.perf_counter() - t0
        build_text = Path(out + ".build.log").read_text()
        for ln in build_text.splitlines():
            if ln.startswith(("WARNING", "ERROR", "CRITICAL")):
                print(f"container build: {ln}", file=sys.stderr)
        cmd = read_model_description(str(container))
        cvars = {v.name for v in cmd.modelVariables}
        missing = [nm for nm in out_names if nm not in cvars]
        if missing:
            fail(f"the container does not expose {missing}")
        # Parameters are exposed as `<fmu id>.<name>`.
        sc.parameters = {f"{fmu_id}.{k}": v for k, v in sc.parameters.items()}
        logs = LogCollector(version, out + ".container.log")
        try:
            result, _, wall = simulate(str(container), sc, out_names=out_names, md=cmd,
                                       debug_logging=True, logger=logs.callback)
        finally:
            logs.file.close()
    write_csv(out, out_names, ([r[c] for c in ["time"] + out_names] for r in result))
    counts = {}
    for status, _, _ in logs.messages:
        counts[STATUS[status]] = counts.get(STATUS[status], 0) + 1
    # The embedded FMU's messages come prefixed with its file name; the container's own messages
    # use the Warning and Error statuses for information too (its version, its settings), so
    # only the FMU's are judged.
    prefix = f"{Path(fmu).name}:"
    from_fmu = [(status, m) for status, _, m in logs.messages if m.startswith(prefix)]
    print(f"fmutool-container: FMI {version}.0 container built in {build_wall:.3f} s; "
          f"{len(logs.messages)} log messages {counts}, {len(from_fmu)} from the embedded FMU", file=sys.stderr)
    for status, _, message in logs.messages:
        if status >= 1:
            who = "FMU" if message.startswith(prefix) else "container"
            print(f"container log ({who}): [{STATUS[status]}] {message}", file=sys.stderr)
    print(f"fmutool-container: {wall:.3f} s", file=sys.stderr)
    if not logs.messages:
        fail("debug logging was on but the container logged nothing")
    if any(status >= 3 for status, _ in from_fmu):
        fail(f"the embedded FMU logged an error (whole log: {out}.container.log)")


# ------------------------------------------------------------------------------------ libcosim
def run_libcosim(fmu, scenario, out):
    from libcosimpy.CosimEnums import CosimVariableCausality, CosimVariableType
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimManipulator import CosimManipulator
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy.CosimSlave import CosimLocalSlave
    from libcosimpy._internal import get_last_error_message

    sc = Scenario(scenario)
    md = read_model_description(fmu)
    variables, names, table = scenario_inputs(md, sc)
    out_names = output_names(md, sc)
    step_ns = round(sc.h * 1e9)
    if abs(step_ns - sc.h * 1e9) > 1e-6:
        fail(f"libcosim counts time in whole nanoseconds; the step {sc.h} s is not one")

    log_output_level(CosimLogLevel.WARNING)
    t0 = time.perf_counter()
    ex = CosimExecution.from_step_size(step_size=step_ns)
    local = CosimLocalSlave(fmu_path=str(Path(fmu).resolve()), instance_name="servo")
    # An archive libcosim refuses (FMI 3.0: its FMI Library reads 1.0 and 2.0) leaves a null
    # slave, which add_local_slave would dereference: the refusal is reported with libcosim's
    # own reason.
    if not local.ptr():
        fail(f"libcosim cannot load {fmu}: {get_last_error_message()}")
    slave = ex.add_local_slave(local)
    info = {v.name.decode(): v for v in ex.slave_variables(slave)}
    unknown = [nm for nm in list(sc.parameters) + names + out_names if nm not in info]
    if unknown:
        fail(f"libcosim does not list {unknown} among the FMU's variables")
    real, integer, boolean = CosimVariableType.REAL.value, CosimVariableType.INTEGER.value, CosimVariableType.BOOLEAN.value

    def initial(nm, value):
        v = info[nm]
        if v.type == real:
            ok = ex.real_initial_value(slave, v.reference, float(value))
        elif v.type == integer:
            ok = ex.integer_initial_value(slave, v.reference, int(value))
        elif v.type == boolean:
            ok = ex.boolean_initial_value(slave, v.reference, bool(value))
        else:
            fail(f"{nm}: type {v.type} is not handled")
        if not ok:
            fail(f"libcosim refused {nm} = {value}: {get_last_error_message()}")

    for nm, value in sc.parameters.items():
        if nm not in info or info[nm].causality != CosimVariableCausality.PARAMETER.value:
            fail(f"scenario parameter {nm!r} is not a parameter of the FMU")
        initial(nm, value)
    for nm in names:
        initial(nm, table[0][nm])
    setter = CosimManipulator.create_override()
    ex.add_manipulator(setter)
    last = CosimObserver.create_last_value()
    ex.add_observer(last)
    series = CosimObserver.create_time_series()
    ex.add_observer(series)
    outputs = [info[nm] for nm in out_names]
    for v in outputs:
        if v.type not in (real, integer):
            fail(f"{v.name.decode()}: type {v.type} is not handled")
        series.start_time_series(slave, v.reference, CosimVariableType(v.type))

    def override(nm, value):
        v = info[nm]
        if v.type == real:
            setter.slave_real_values(slave, [v.reference], [float(value)])
        elif v.type == integer:
            setter.slave_integer_values(slave, [v.reference], [int(value)])
        else:
            setter.slave_boolean_values(slave, [v.reference], [bool(value)])

    rows = []
    for k in range(sc.n):
        if k > 0:
            for nm in names:
                if table[k][nm] != table[k - 1][nm]:
                    override(nm, table[k][nm])
        if not ex.step():
            fail(f"libcosim's step {k + 1} failed: {get_last_error_message()}")
        rows.append([(k + 1) * sc.h] + [
            (last.last_real_values if v.type == real else last.last_integer_values)(slave, [v.reference])[0]
            for v in outputs
        ])
    # The values at t = 0 (after initialisation): libcosimpy 0.0.6 drops the samples of step
    # number 0 from a read's tail, so two are read and the first kept.
    first = [0.0]
    for v in outputs:
        read = series.time_series_real_samples if v.type == real else series.time_series_integer_samples
        _, steps, values = read(slave, v.reference, from_step=0, sample_count=2)
        if not steps or steps[0] != 0:
            fail(f"libcosim has no sample of {v.name.decode()} at step 0")
        first.append(values[0])
    wall = time.perf_counter() - t0
    write_csv(out, out_names, [first] + rows)
    print(f"libcosim: {wall:.3f} s", file=sys.stderr)


def main():
    faulthandler.enable()  # a crash inside an FMU or an importer's library says where
    a = sys.argv[1:]
    usage = __doc__.split("Usage:")[1].split("Each command")[0]
    if a[:1] == ["ecospy"] and len(a) == 4:
        run_ecospy(a[1], a[2], a[3])
    elif a[:1] == ["libcosim"] and len(a) == 4:
        run_libcosim(a[1], a[2], a[3])
    elif a[:1] == ["fmutool-check"] and len(a) == 2:
        run_fmutool_check(a[1])
    elif a[:1] == ["fmutool-container"] and len(a) == 4:
        run_fmutool_container(a[1], a[2], a[3])
    else:
        sys.exit(f"usage:{usage}")


if __name__ == "__main__":
    main()
