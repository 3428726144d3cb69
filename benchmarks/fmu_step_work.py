"""The work of one doStep: the figures behind the native FMU's ``max_evaluations`` default.

For every shipped case (cases/*.toml) the case's native FMU (build/<Name>Native.fmu, built by
``make mechanisms``) runs the case in-process through FMPy: its parameters, its step and ramp
events applied at the communication points they name, on its grid, at its tolerances and, for
the tests' tightest setting, at rtol = atol = 1e-13.  With logging on, fmi2Terminate's statistics
give the most right-hand-side evaluations one doStep took; the largest over all runs, against the
default cap, is the margin docs/fmi_hosts.md quotes.  Then the runaway doStep the cap ends
(case1 with omega2_start = 1e15, the native and the pythonfmu FMU): how long the call takes with
the default cap (wall clock of the one doStep; the machine's load moves it).

    .venv/bin/python benchmarks/fmu_step_work.py [--skip-pythonfmu]
"""
from __future__ import annotations

import argparse
import math
import re
import sys
import time
import tomllib
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
_MOST = re.compile(r"at most (\d+) right-hand-side evaluations in one communication step \(max_evaluations = (\S+)\)")


@dataclass(frozen=True)
class StepWork:
    case: str
    tolerance: str
    most: int            # the most right-hand-side evaluations of one doStep
    cap: float


def _native_fmu(case: dict) -> Path:
    return ROOT / "build" / (Path(case["fmu"]).stem + "Native.fmu")


def run_case(path: Path, tolerances: dict | None) -> StepWork:
    """One case on its native FMU (step and ramp events applied at the communication points)."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    case = tomllib.loads(path.read_text())
    fmu = _native_fmu(case)
    md = read_model_description(str(fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    messages = []
    unzipped = extract(str(fmu))
    slave = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier,
                      instanceName="work")
    slave.instantiate(loggingOn=True, callbacks=_callbacks(messages))
    exp = case["experiment"]
    start, stop, step = float(exp["start"]), float(exp["stop"]), float(exp["step"])
    values = {k: float(v) for k, v in case.get("parameters", {}).items()}
    values.update(tolerances or {})
    slave.setupExperiment(startTime=start)
    slave.enterInitializationMode()
    slave.setReal([vr[k] for k in values], list(values.values()))
    slave.exitInitializationMode()
    n = round((stop - start) / step)
    for k in range(n):
        t = start + k * step
        for event in case.get("events", []):
            if event["type"] == "step" and math.isclose(t, float(event["time"])):
                slave.setReal([vr[event["variable"]]], [float(event["value"])])
            elif event["type"] == "ramp" and float(event["start"]) <= t <= float(event["end"]) + 1e-12:
                f = (t - float(event["start"])) / (float(event["end"]) - float(event["start"]))
                slave.setReal([vr[event["variable"]]], [float(event["from"]) + f * (float(event["to"]) - float(event["from"]))])
        slave.doStep(t, step)
    slave.terminate()
    slave.freeInstance()
    found = [m for m in map(_MOST.search, messages) if m]
    label = "the case's" if not tolerances else f"rtol = atol = {tolerances['rtol']:g}"
    return StepWork(path.stem, label, int(found[-1].group(1)), float(found[-1].group(2)))


def _callbacks(messages):
    """fmi2CallbackFunctions whose logger appends each message to `messages` (keep it alive)."""
    from fmpy.fmi2 import (defaultCallbacks, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)

    def log(component, instance, status, category, message):
        messages.append(message.decode(errors="replace"))

    callbacks = fmi2CallbackFunctions()
    callbacks.logger = fmi2CallbackLoggerTYPE(log)
    callbacks.allocateMemory = defaultCallbacks.allocateMemory
    callbacks.freeMemory = defaultCallbacks.freeMemory
    from ctypes import byref

    from fmpy.logging import addLoggerProxy

    addLoggerProxy(byref(callbacks))       # formats the message's "%s" arguments
    return callbacks


def runaway(fmu: Path) -> tuple[float, str]:
    """One doStep of 0.01 s of case 1 at omega2_start = 1e15 with the default cap: (seconds, message)."""
    from fmpy import extract, read_model_description
    from fmpy.fmi1 import FMICallException
    from fmpy.fmi2 import FMU2Slave

    md = read_model_description(str(fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    slave = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(fmu)), modelIdentifier=md.coSimulation.modelIdentifier,
                      instanceName="runaway")
    messages = []
    slave.instantiate(loggingOn=True, callbacks=_callbacks(messages))
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.setReal([vr["omega2_start"]], [1e15])
    slave.exitInitializationMode()
    begin = time.perf_counter()
    try:
        slave.doStep(0.0, 0.01)
        outcome = "returned OK"
    except FMICallException as exc:
        outcome = f"status {exc.status}"
    seconds = time.perf_counter() - begin
    text = next((m for m in messages if "max_evaluations" in m), "")
    return seconds, f"{outcome}: {text}"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--skip-pythonfmu", action="store_true", help="time the runaway step on the native FMU only")
    args = parser.parse_args(argv)
    rows = []
    for path in sorted((ROOT / "cases").glob("*.toml")):
        for tolerances in (None, {"rtol": 1e-13, "atol": 1e-13}):
            work = run_case(path, tolerances)
            rows.append(work)
            print(f"{work.case:32s} {work.tolerance:22s} most evaluations in one doStep: {work.most:6d}")
    most = max(rows, key=lambda w: w.most)
    print(f"largest: {most.most} ({most.case}, {most.tolerance}); default max_evaluations = {most.cap:g}: "
          f"{most.cap / most.most:.0f}x")
    fmus = [ROOT / "build" / "FourBarNative.fmu"] + ([] if args.skip_pythonfmu else [ROOT / "build" / "FourBar.fmu"])
    for fmu in fmus:
        seconds, text = runaway(fmu)
        print(f"runaway doStep (omega2_start = 1e15) on {fmu.name}: {seconds:.3f} s, {text}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
