"""Every parameter and input of the FMU, read back through fmpy right after instantiation,
must equal its start value in the model description: a check that each value reference
reaches its own variable (the FMU's getters route value references through its fields).

Usage: fmpy_start_values.py FMU   (prints one line per mismatch; exit 1 if any)
"""
import shutil
import sys

from fmpy import extract, read_model_description
from fmpy.fmi3 import FMU3Slave


def main():
    fmu = sys.argv[1]
    md = read_model_description(fmu)
    unzipdir = extract(fmu)
    slave = FMU3Slave(guid=md.guid, unzipDirectory=unzipdir, modelIdentifier=md.coSimulation.modelIdentifier, instanceName="start_values")
    slave.instantiate()
    slave.enterInitializationMode()
    bad = 0
    checked = 0
    for v in md.modelVariables:
        if v.causality not in ("parameter", "input") or v.start is None:
            continue
        checked += 1
        if v.type == "Float64":
            got = slave.getFloat64([v.valueReference])[0]
            want = float(v.start)
        elif v.type == "Int32":
            got = slave.getInt32([v.valueReference])[0]
            want = int(v.start)
        elif v.type == "Boolean":
            got = bool(slave.getBoolean([v.valueReference])[0])
            want = str(v.start).lower() == "true"
        else:
            continue
        if got != want:
            bad += 1
            print(f"{v.name} (vr {v.valueReference}): read {got!r}, start value {want!r}")
    slave.exitInitializationMode()
    slave.terminate()
    slave.freeInstance()
    shutil.rmtree(unzipdir, ignore_errors=True)
    print(f"checked {checked} variables, {bad} mismatches")
    sys.exit(1 if bad else 0)


if __name__ == "__main__":
    main()
