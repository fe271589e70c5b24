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


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("fmu")
    ap.add_argument("scenario")
    ap.add_argument("out")
    ap.add_argument("--timing", help="write wall-clock timing of the simulation as JSON")
    a = ap.parse_args()

    with open(a.scenario, "rb") as f:
        sc = tomllib.load(f)
    h = float(sc.get("step", DEFAULT_STEP))
    stop = float(sc["stop_time"])
    n = int(round(stop / h))
    events = sc.get("events", [])

    md = read_model_description(a.fmu)
    variables = {v.name: v for v in md.modelVariables}
    for nm in sorted({k for e in events for k in e if k != "time"}):
        if nm not in variables or variables[nm].causality != "input":
            sys.exit(f"scenario sets {nm!r}, which is not an input of the FMU")
    # Every input gets a column (its start value until an event sets it).
    names = sorted(v.name for v in md.modelVariables if v.causality == "input")
    start = {}
    for nm in names:
        v = variables[nm]
        if v.type == "Boolean":
            start[nm] = str(v.start).lower() == "true"
        elif v.type == "Int32":
            start[nm] = int(v.start)
        else:
            start[nm] = float(v.start)

    dtype = [("time", np.float64)]
    for nm in names:
        t = variables[nm].type
        dtype.append((nm, np.int32 if t == "Int32" else (np.bool_ if t == "Boolean" else np.float64)))
    table = input_table(events, names, n, h, start)
    rows = [tuple([0.0 + k * h] + [table[k][nm] for nm in names]) for k in range(n + 1)]
    signals = np.array(rows, dtype=dtype)

    discrete = [
        nm for nm in names if variables[nm].type in ("Int32", "Boolean") or variables[nm].variability == "discrete"
    ]

    def step_finished(t, recorder):
        if discrete:
            k = min(int(round(t / h)), n)
            vals = table[k]
            for nm in discrete:
                v = variables[nm]
                if v.type == "Int32":
                    recorder.fmu.setInt32([v.valueReference], [int(vals[nm])])
                elif v.type == "Float64":
                    recorder.fmu.setFloat64([v.valueReference], [float(vals[nm])])
                else:
                    recorder.fmu.setBoolean([v.valueReference], [bool(vals[nm])])
        return True

    outputs = sorted((v for v in md.modelVariables if v.causality == "output"), key=lambda v: v.valueReference)
    out_names = [v.name for v in outputs]
    if sc.get("record"):
        # The scenario's `record` list, in its order, as the Rust host records it.
        unknown = [nm for nm in sc["record"] if nm not in out_names]
        if unknown:
            sys.exit(f"record lists {unknown}, which are not outputs of the FMU")
        out_names = list(sc["record"])
    start_values = dict(sc.get("parameters", {}))
    t0 = time.perf_counter()
    result = fmpy.simulate_fmu(
        a.fmu,
        start_time=0.0,
        stop_time=stop,
        step_size=h,
        output_interval=h,
        start_values=start_values,
        input=signals,
        output=out_names,
        step_finished=step_finished,
        fmi_type="CoSimulation",
    )
    wall = time.perf_counter() - t0

    with open(a.out, "w") as f:
        f.write(",".join(["time"] + out_names) + "\n")
        for r in result:
            f.write(",".join(repr(float(r[c])) for c in ["time"] + out_names) + "\n")
    if a.timing:
        with open(a.timing, "w") as f:
            json.dump({"wall_seconds": wall, "simulated_seconds": stop, "steps": n}, f)


if __name__ == "__main__":
    main()
