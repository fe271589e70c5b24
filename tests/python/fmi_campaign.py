#!/usr/bin/env python3
"""Random FMI call sequences through fmpy: the FMU must never crash, hang or return OK with a
non-finite output, whatever the calls, their order and their arguments.

Each sequence instantiates the FMU (FMI 3.0 or 2.0) and makes random calls from every
function fmpy wraps for a Co-Simulation FMU, in any order (wrong states included), with
valid, invalid and hostile arguments (unknown value references, NaN, infinities, huge
values, step sizes of 0, negative, 1e300 or off the grid, foreign and corrupt serialized
states). A call that hangs longer than --call-timeout seconds is a hang (SIGALRM); a crash
kills this process, and the caller sees it (exit status and the faulthandler traceback with
the seed and the last call, printed before each call with --trace).

Usage: fmi_campaign.py FMU [--seconds 20] [--seed 1] [--json OUT.json]
Prints a JSON summary on stdout.
"""
import argparse
import faulthandler
import json
import math
import random
import shutil
import signal
import sys
import time

from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave

HOSTILE_FLOATS = [math.nan, math.inf, -math.inf, 1e300, -1e300, 1e200, -4e30, 3.4e38, 5e-324, 0.0, -0.0, 1.0, -1.0]
HOSTILE_INTS = [0, 1, -1, 2, 3, 7, 2**31 - 1, -(2**31), 1000, 1001, 99]


class Hang(Exception):
    pass


def on_alarm(signum, frame):
    raise Hang()


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("fmu")
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--calls-per-sequence", type=int, default=60)
    ap.add_argument("--call-timeout", type=float, default=20.0)
    ap.add_argument("--trace", action="store_true", help="print every call before making it (to find a crash)")
    a = ap.parse_args()
    faulthandler.enable()
    signal.signal(signal.SIGALRM, on_alarm)

    md = read_model_description(a.fmu)
    version = md.fmiVersion
    unzipdir = extract(a.fmu)
    variables = md.modelVariables
    by_type = {}
    for v in variables:
        by_type.setdefault(v.type, []).append(v)
    floats = by_type.get("Float64", []) + by_type.get("Real", [])
    ints = by_type.get("Int32", []) + by_type.get("Integer", [])
    bools = by_type.get("Boolean", [])
    float_outputs = [v.valueReference for v in floats if v.causality == "output"]
    max_vr = max(v.valueReference for v in variables)
    token = md.guid
    identifier = md.coSimulation.modelIdentifier

    rng = random.Random(a.seed)
    stats = {
        "fmi_version": version,
        "sequences": 0,
        "calls": 0,
        "statuses": {"ok": 0, "warning": 0, "error": 0, "exception": 0},
        "hangs": 0,
        "ok_with_non_finite_output": 0,
        "steps_ok": 0,
        "crashes": 0,
    }
    findings = []
    deadline = time.monotonic() + a.seconds

    def vr_of(pool):
        r = rng.random()
        if r < 0.8 and pool:
            return rng.choice(pool).valueReference
        if r < 0.9:
            return rng.randint(0, max_vr)
        return rng.choice([max_vr + 1, 2**32 - 1, 10**6])

    def value_float(v=None):
        if rng.random() < 0.6 and v is not None and v.start not in (None, ""):
            try:
                x = float(v.start)
            except ValueError:
                x = 0.0
            return x * rng.choice([1.0, 0.5, 2.0, -1.0, 10.0, 1e3])
        return rng.choice(HOSTILE_FLOATS + [rng.uniform(-1e3, 1e3)])

    def value_int():
        return rng.choice(HOSTILE_INTS + [rng.randint(-10, 10)])

    serialized_pool = []

    while time.monotonic() < deadline:
        stats["sequences"] += 1
        seed = rng.randrange(2**32)
        srng = random.Random(seed)
        if version.startswith("3"):
            fmu = FMU3Slave(guid=token, unzipDirectory=unzipdir, modelIdentifier=identifier, instanceName="campaign")
        else:
            fmu = FMU2Slave(guid=token, unzipDirectory=unzipdir, modelIdentifier=identifier, instanceName="campaign")
        states = []
        t = 0.0

        def log(*args):
            pass

        try:
            if version.startswith("3"):
                fmu.instantiate(loggingOn=srng.random() < 0.5, logMessage=lambda *x: None)
            else:
                fmu.instantiate(loggingOn=srng.random() < 0.5)
        except Exception as e:  # a refused instantiation is an answer, not a crash
            findings.append(f"instantiate refused: {e}")
            continue

        def call(name, f):
            nonlocal t
            stats["calls"] += 1
            if a.trace:
                print(f"seed {seed} call {name}", file=sys.stderr, flush=True)
            signal.setitimer(signal.ITIMER_REAL, a.call_timeout)
            try:
                r = f()
                stats["statuses"]["ok"] += 1
                return r
            except FMICallException as e:
                key = "warning" if e.status == 1 else "error"
                stats["statuses"][key] += 1
            except Hang:
                stats["hangs"] += 1
                findings.append(f"hang: seed {seed}, {name}")
            except Exception:
                # fmpy's own argument conversions (ctypes) refusing a hostile value.
                stats["statuses"]["exception"] += 1
            finally:
                signal.setitimer(signal.ITIMER_REAL, 0)
            return None

        def do_step():
            nonlocal t
            h = srng.choice([0.00025, 0.00025, 0.0005, 0.001, 0.0003, 0.0, -0.00025, 1e300, math.nan, 0.1, 2000.0])
            current = t if srng.random() < 0.85 else srng.choice([0.0, t + 1.0, math.nan, -1.0])
            fmu.doStep(current, h)
            t = current + h
            stats["steps_ok"] += 1
            if float_outputs:
                values = fmu.getFloat64(float_outputs) if version.startswith("3") else fmu.getReal(float_outputs)
                if any(not math.isfinite(x) for x in values):
                    stats["ok_with_non_finite_output"] += 1
                    findings.append(f"OK step with a non-finite output: seed {seed}, t = {t}")

        v3 = version.startswith("3")
        menu = [
            ("enterInitializationMode", lambda: fmu.enterInitializationMode(startTime=srng.choice([0.0, 0.0, 0.1, math.nan]), stopTime=srng.choice([None, 10.0, -1.0])) if v3 else (fmu.setupExperiment(startTime=srng.choice([0.0, 0.1, math.nan])), fmu.enterInitializationMode())),
            ("exitInitializationMode", lambda: fmu.exitInitializationMode()),
            ("doStep", do_step),
            ("doStep", do_step),
            ("doStep", do_step),
            ("setFloat", lambda: (fmu.setFloat64 if v3 else fmu.setReal)([vr_of(floats)], [value_float(srng.choice(floats) if floats else None)])),
            ("setInt", lambda: (fmu.setInt32 if v3 else fmu.setInteger)([vr_of(ints)], [value_int()])),
            ("setBoolean", lambda: fmu.setBoolean([vr_of(bools)], [srng.random() < 0.5])),
            ("getFloat", lambda: (fmu.getFloat64 if v3 else fmu.getReal)([vr_of(floats) for _ in range(srng.randint(0, 5))])),
            ("getInt", lambda: (fmu.getInt32 if v3 else fmu.getInteger)([vr_of(ints)])),
            ("getBoolean", lambda: fmu.getBoolean([vr_of(bools)])),
            ("terminate", lambda: fmu.terminate()),
            ("reset", lambda: fmu.reset()),
            ("getFMUState", lambda: states.append((fmu.getFMUState if v3 else fmu.getFMUstate)())),
            ("setFMUState", lambda: (fmu.setFMUState if v3 else fmu.setFMUstate)(srng.choice(states)) if states else None),
            ("freeFMUState", lambda: (fmu.freeFMUState if v3 else fmu.freeFMUstate)(states.pop(srng.randrange(len(states)))) if states else None),
            ("serialize", lambda: serialized_pool.append((fmu.serializeFMUState if v3 else fmu.serializeFMUstate)(srng.choice(states))) if states else None),
            ("deserialize", lambda: states.append((fmu.deserializeFMUState if v3 else fmu.deSerializeFMUstate)(mutate(srng, srng.choice(serialized_pool)))) if serialized_pool else None),
            ("setDebugLogging", lambda: fmu.setDebugLogging(srng.random() < 0.5, srng.choice([[], ["logEvents"], ["noSuchCategory"]]))),
        ]
        if v3:
            menu += [
                ("enterEventMode", lambda: fmu.enterEventMode()),
                ("enterStepMode", lambda: fmu.enterStepMode()),
                ("updateDiscreteStates", lambda: fmu.updateDiscreteStates()),
                ("getDirectionalDerivative", lambda: fmu.getDirectionalDerivative([vr_of(floats)], [vr_of(floats)], [1.0])),
                ("getOutputDerivatives", lambda: fmu.getOutputDerivatives([vr_of(floats)], [1])),
                ("getFloat32", lambda: fmu.getFloat32([vr_of(floats)])),
                ("setString", lambda: fmu.setString([vr_of(floats)], ["x"])),
            ]
        else:
            menu += [
                ("cancelStep", lambda: fmu.cancelStep()),
                ("getRealStatus", lambda: fmu.getRealStatus(srng.choice([0, 1, 2, 3, 99]))),
                ("getBooleanStatus", lambda: fmu.getBooleanStatus(srng.choice([0, 1, 2, 3, 99]))),
                ("getDirectionalDerivative", lambda: fmu.getDirectionalDerivative([vr_of(floats)], [vr_of(floats)], [1.0])),
            ]
        # A usual start half of the time, so later calls reach Step Mode often.
        if srng.random() < 0.5:
            call("enterInitializationMode", lambda: fmu.enterInitializationMode() if v3 else (fmu.setupExperiment(), fmu.enterInitializationMode()))
            call("exitInitializationMode", lambda: fmu.exitInitializationMode())
            t = 0.0
        for _ in range(a.calls_per_sequence):
            name, f = srng.choice(menu)
            call(name, f)
        for s in states:
            call("freeFMUState", lambda: (fmu.freeFMUState if v3 else fmu.freeFMUstate)(s))
        call("freeInstance", lambda: fmu.freeInstance())
        if len(serialized_pool) > 50:
            serialized_pool[:] = serialized_pool[-20:]

    shutil.rmtree(unzipdir, ignore_errors=True)
    stats["findings"] = findings[:20]
    print(json.dumps(stats))


def mutate(rng, data):
    """A serialized state as saved, or corrupted: a flipped byte, truncated, extended, garbage."""
    r = rng.random()
    b = bytearray(data)
    if r < 0.4 or not b:
        return bytes(b)
    if r < 0.6:
        i = rng.randrange(len(b))
        b[i] ^= 1 << rng.randrange(8)
        return bytes(b)
    if r < 0.7:
        return bytes(b[: rng.randrange(len(b))])
    if r < 0.8:
        return bytes(b) + bytes(rng.randrange(256) for _ in range(rng.randint(1, 16)))
    return bytes(rng.randrange(256) for _ in range(rng.choice([0, 1, 28, len(b)])))


if __name__ == "__main__":
    main()
