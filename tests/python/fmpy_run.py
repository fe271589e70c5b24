#!/usr/bin/env python3
"""Run a servo scenario (TOML) on the FMU with fmpy.simulate_fmu and write a CSV.

This is the independent importer of the cross-check: it reads the scenario file itself and
drives the FMU through fmpy, so a difference with `servo run` points at the FMU or at one of
the two importers. Semantics, as in the Rust host:
  * parameters are start values;
  * an event at time t sets inputs for the step that starts at t and holds them;
  * outputs are sampled after initialisation and after every step (the scenario's `record`
    list, or every output).

fmpy applies continuous inputs by linear interpolation: the input table has one row per
communication point (t_k = k*h), so at t_k the interpolation weight of the previous row is
exactly 0 and the value is the row's own, bit for bit. fmpy applies discrete inputs (Int32,
Boolean, and Float64 of discrete variability) only at initialisation in co-simulation without
event mode, so they are set in the step_finished callback, before the next step, from the
same table.

FMI 2.0 archives run the same way: their type names (Integer, Real) and setters (setInteger,
setReal) stand for FMI 3.0's Int32 and Float64; fmpy calls step_finished after every doStep
in both versions, so the discrete inputs of the step starting at t are set at t in both.

The scenario, input-table, output-list and CSV helpers are shared with importers.py.

Usage: fmpy_run.py FMU SCENARIO.toml OUT.csv [--timing OUT.json]
"""
import argparse
import json
import sys
import time
import tomllib

import numpy as np
import fmpy
from fmpy import read_model_description

DEFAULT_STEP = 4.0 / 16000.0

# Type names of FMI 3.0 and FMI 2.0 for the same variables.
INT_TYPES = ("Int32", "Integer")
REAL_TYPES = ("Float64", "Real")


class Scenario:
    """A scenario file as both runners read it: communication step, stop time, steps, events."""

    def __init__(self, path):
        with open(path, "rb") as f:
            self.data = tomllib.load(f)
        self.h = float(self.data.get("step", DEFAULT_STEP))
        self.stop = float(self.data["stop_time"])
        self.n = int(round(self.stop / self.h))
        self.events = self.data.get("events", [])
        self.parameters = dict(self.data.get("parameters", {}))
        self.record = self.data.get("record")


def input_table(events, names, n, h, start):
    """Input values at every communication point k = 0..n (events in time order; one pass)."""
    rows = []
    values = dict(start)
    i = 0
    for k in range(n + 1):
        t = k * h
        while i < len(events) and events[i]["time"] <= t + 1e-9 * h:
            for nm in names:
                if nm in events[i]:
                    values[nm] = events[i][nm]
            i += 1
        rows.append(dict(values))
    return rows


def start_value(v):
    """A variable's start value as a Python bool, int or float."""
    if v.type == "Boolean":
        return str(v.start).lower() == "true"
    if v.type in INT_TYPES:
        return int(v.start)
    return float(v.start)


def is_discrete_input(v):
    return v.type in INT_TYPES or v.type == "Boolean" or v.variability == "discrete"


def set_value(fmu, v, value):
    """Set one variable through fmpy's setter for its FMI version and type."""
    if v.type in INT_TYPES:
        (fmu.setInt32 if v.type == "Int32" else fmu.setInteger)([v.valueReference], [int(value)])
    elif v.type in REAL_TYPES:
        (fmu.setFloat64 if v.type == "Float64" else fmu.setReal)([v.valueReference], [float(value)])
    else:
        fmu.setBoolean([v.valueReference], [bool(value)])


def scenario_inputs(md, sc):
    """(inputs by name, input names, the input table) of `sc` on the FMU of `md`; exits on an
    event that sets a variable which is not an input."""
    variables = {v.name: v for v in md.modelVariables}
    for nm in sorted({k for e in sc.events for k in e if k != "time"}):
        if nm not in variables or variables[nm].causality != "input":
            sys.exit(f"scenario sets {nm!r}, which is not an input of the FMU")
    # Every input gets a column (its start value until an event sets it).
    names = sorted(v.name for v in md.modelVariables if v.causality == "input")
    start = {nm: start_value(variables[nm]) for nm in names}
    return variables, names, input_table(sc.events, names, sc.n, sc.h, start)


# The order the Rust host records every output in: the Float64 outputs, then the Int32 ones,
# then the Boolean ones (FMI 2.0's Real, Integer, Boolean), each in value-reference order.
TYPE_RANK = {"Float64": 0, "Real": 0, "Int32": 1, "Integer": 1, "Boolean": 2}


def output_names(md, sc):
    """The recorded outputs: the scenario's `record` list in its order, as the Rust host records
    it, or every output as the Rust host orders them (TYPE_RANK, then value reference); exits
    on a name that is not an output."""
    outputs = sorted(
        (v for v in md.modelVariables if v.causality == "output"),
        key=lambda v: (TYPE_RANK.get(v.type, 3), v.valueReference),
    )
    out_names = [v.name for v in outputs]
    if sc.record:
        unknown = [nm for nm in sc.record if nm not in out_names]
        if unknown:
            sys.exit(f"record lists {unknown}, which are not outputs of the FMU")
        out_names = list(sc.record)
    return out_names


def simulate(fmu_path, sc, out_names=None, md=None, **fmpy_options):
    """Run `sc` on the FMU with fmpy.simulate_fmu; returns (result, recorded names, wall seconds).
    `out_names` defaults to output_names(); extra keyword arguments go to simulate_fmu."""
    md = md or read_model_description(fmu_path)
    variables, names, table = scenario_inputs(md, sc)
    h, n = sc.h, sc.n

    dtype = [("time", np.float64)]
    for nm in names:
        t = variables[nm].type
        dtype.append((nm, np.int32 if t in INT_TYPES else (np.bool_ if t == "Boolean" else np.float64)))
    rows = [tuple([0.0 + k * h] + [table[k][nm] for nm in names]) for k in range(n + 1)]
    signals = np.array(rows, dtype=dtype)

    discrete = [nm for nm in names if is_discrete_input(variables[nm])]

    def step_finished(t, recorder):
        if discrete:
            k = min(int(round(t / h)), n)
            vals = table[k]
            for nm in discrete:
                set_value(recorder.fmu, variables[nm], vals[nm])
        return True

    if out_names is None:
        out_names = output_names(md, sc)
    t0 = time.perf_counter()
    result = fmpy.simulate_fmu(
        fmu_path,
        start_time=0.0,
        stop_time=sc.stop,
        step_size=h,
        output_interval=h,
        start_values=dict(sc.parameters),
        input=signals,
        output=out_names,
        step_finished=step_finished,
        fmi_type="CoSimulation",
        **fmpy_options,
    )
    return result, out_names, time.perf_counter() - t0


def write_csv(path, names, rows):
    """Header `time,<names>`, then one line per row (time first), every value as repr(float)."""
    with open(path, "w") as f:
        f.write(",".join(["time"] + list(names)) + "\n")
        for r in rows:
            f.write(",".join(repr(float(x)) for x in r) + "\n")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("fmu")
    ap.add_argument("scenario")
    ap.add_argument("out")
    ap.add_argument("--timing", help="write wall-clock timing of the simulation as JSON")
    a = ap.parse_args()

    sc = Scenario(a.scenario)
    result, out_names, wall = simulate(a.fmu, sc)
    write_csv(a.out, out_names, ([r[c] for c in ["time"] + out_names] for r in result))
    if a.timing:
        with open(a.timing, "w") as f:
            json.dump({"wall_seconds": wall, "simulated_seconds": sc.stop, "steps": sc.n}, f)


if __name__ == "__main__":
    main()
