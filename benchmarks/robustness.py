#!/usr/bin/env python3
"""Robustness beyond Table 1: detection and diagnosis on a fixed, seeded sample of generated
configurations (fmu_src/fourbar_configurations.py), written to docs/robustness.md.

Families (``configurations.FAMILIES``), each drawn ``--per-family`` times and run twice,
noise-free and with σ = 3-5 mm (drawn) on x2, the monitored column:

``table1_swing``  Table 1's linkage and masses, swinging from other start angles and rates;
``rotating``      crank-rockers (Grashof, crank shortest) turning all the way round;
``other_swing``   other geometries, Grashof and not, swinging.

Every configuration gets three runs on the native FMU, each monitored at the monitor's
default settings (``--model``: Prophet unless told otherwise) and diagnosed after an alarm:

- healthy, ``--healthy`` s long: every alarm is false;
- a 1 % step of one length (L1-L4, drawn, either sign) at a grid time in 15-40 s;
- a 10 % step of one mass (m2-m4, drawn, either sign), the same way.
Runs with a fault end 20 s after it.  Faults are drawn only where the stepped linkage still
moves steadily from every state of the healthy motion (``configurations.fault_is_safe``).

Each scenario is one task of :func:`sweep.scenario.run_scenario` (the sweep's own runner:
orchestrator run, monitor replay, diagnosis) on a local Dask cluster (``--workers``, default
one per core).  Rows are cached as JSON under ``--out`` (default out/benchmarks/robustness)
the moment they finish, keyed by the scenario and by a fingerprint of the code and the FMU
that produced them: a rerun (or a run in chunks with ``--limit``) runs only what is missing
or was measured on other code.  Ctrl-C keeps every finished row.

Usage:
  python benchmarks/robustness.py [--write docs/robustness.md] [--out DIR] [--per-family N]
                                  [--healthy S] [--model prophet|harmonic] [--workers N]
                                  [--limit N] [--quick]
``--quick``: one configuration per family, noise-free only, a 30 s healthy run and the length
step, the harmonic model (a smoke test of the whole chain; its figures mean nothing).

``--mechanisms``: the same runs on the user-style families of benchmarks/mechanism_families.py
(a quick-return, six-bars, a drag link, an inverted slider-crank: mechanism files, not the
four-bar's generated geometry), written to their own part of the page ("# User-style
mechanisms"); a four-bar ``--write`` keeps that part, and a ``--mechanisms --write`` keeps the rest.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import signal
import statistics
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(HERE))

from fmu_src import fourbar_configurations as C  # noqa: E402
from robustness_page import USER_PART, write_part  # noqa: E402

NATIVE = REPO / "build" / "FourBarNative.fmu"
SEED = 20240623
STEP = 0.01                       # s, the cases' communication step
TRAIN_END = 9.0                   # s, end of the monitor's default training window (0-9 s)
FAULT_TIMES = (15.0, 40.0)        # s, fault time range (after training and the tracker's guard)
AFTER_FAULT = 20.0                # s of run after a fault
NOISE = (0.003, 0.005)            # m, σ on x2 for the noisy variant
LENGTH_STEP = 0.01                # relative size of the length steps
MASS_STEP = 0.10                  # relative size of the mass steps
#: Code whose change changes the figures: the rows measured on other code are run again.
CODE = ("orchestrator", "monitor", "diagnose", "sweep", "fourbar_common")
ROW_SCHEMA = 1


@dataclass(frozen=True)
class Planned:
    """One scenario of the benchmark: a configuration, a noise level, a fault (or none)."""

    key: str                      # cache key (scenario inputs)
    family: str
    config_index: int
    config: C.Configuration | None   # None for a user family (its case is ``text``)
    noise_std: float
    noise_seed: int
    test: str                     # "healthy" | "length" | "mass"
    fault: C.Fault | None
    stop: float
    signal: str = "x2"            # the monitored column
    text: str | None = None       # a user family's case file (the four-bar's is written from config)
    period: float | None = None   # s, a user family's pre-run period (the four-bar's: config.motion)


def _hash(payload) -> str:
    text = json.dumps(payload, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def code_fingerprint(*fmus: Path) -> str:
    """SHA-256 (16 hex digits) of the Python sources in CODE and the FMU files: what a row's
    figures depend on besides its inputs (the configuration is in the row's key)."""
    h = hashlib.sha256()
    files = sorted(p for d in CODE for p in (REPO / d).rglob("*.py"))
    for p in [*files, *fmus]:
        h.update(str(p.relative_to(REPO) if p.is_relative_to(REPO) else p).encode())
        h.update(p.read_bytes())
    return h.hexdigest()[:16]


def plan(per_family: int, healthy: float, model: str, *, noisy: bool = True,
         tests: tuple[str, ...] = ("healthy", "length", "mass")) -> tuple[list[Planned], list[str]]:
    """Every scenario, in a fixed order; and notes on configurations without a safe fault."""
    import numpy as np

    out: list[Planned] = []
    notes: list[str] = []
    for f_index, family in enumerate(C.FAMILIES):
        for i in range(per_family):
            # one generator per configuration: adding configurations never changes earlier ones
            src = C.RandomSource(np.random.default_rng([SEED, f_index, i]))
            config = C.draw_configuration(src, family)
            config = replace(config, named=C.with_names(config, C.PARAMETERS + C.STARTS).named)
            sigma = round(src.uniform(*NOISE), 6)
            seed = src.integer(1, 2**31 - 1)
            faults = {"length": C.draw_fault(src, config, variables=C.LENGTHS, sizes={"length": (LENGTH_STEP,) * 2},
                                             time_range=FAULT_TIMES, step=STEP),
                      "mass": C.draw_fault(src, config, variables=C.MASSES, sizes={"mass": (MASS_STEP,) * 2},
                                           time_range=FAULT_TIMES, step=STEP)}
            for noise_std in ((0.0, sigma) if noisy else (0.0,)):
                for test in tests:
                    fault = faults.get(test)
                    if test != "healthy" and fault is None:
                        notes.append(f"{family} #{i}: no {test} step keeps the motion steady from every state; "
                                     "not run")
                        continue
                    stop = healthy if fault is None else C.on_grid(fault.time + AFTER_FAULT, STEP)
                    payload = {"schema": ROW_SCHEMA, "values": config.values, "noise": [noise_std, seed],
                               "fault": None if fault is None else [fault.variable, fault.value, fault.time],
                               "stop": stop, "model": model}
                    out.append(Planned(key=_hash(payload), family=family, config_index=i, config=config,
                                       noise_std=noise_std, noise_seed=seed, test=test, fault=fault, stop=stop))
    return out, notes


def plan_user(per_family: int, healthy: float, model: str, out: Path, *, noisy: bool = True,
              tests: tuple[str, ...] = ("healthy", "length", "mass")) -> tuple[list[Planned], list[str]]:
    """The user-style families' scenarios (benchmarks/mechanism_families.py), in a fixed order;
    notes on families or configurations that could not be run.  Builds each family's FMU and
    pre-runs each drawn start (seconds each)."""
    import numpy as np

    import mechanism_families as F

    out_plan: list[Planned] = []
    notes: list[str] = []
    for f_index, family in enumerate(F.FAMILIES):
        if not family.path.exists():
            notes.append(f"{family.name}: {family.file} does not exist; not run")
            continue
        try:
            fmu = F.fmu_for(family, out / "fmus")
            values = F.defaults(fmu)
        except RuntimeError as exc:
            notes.append(f"{family.name}: {exc}")
            continue
        lengths, masses = F.stepped(family, fmu)
        print(f"robustness: {family.name}: drawing {per_family} starts ({F.PRE_RUN:g} s pre-run each)",
              file=sys.stderr, flush=True)
        for i in range(per_family):
            rng = np.random.default_rng([SEED, 100 + f_index, i])
            config = F.draw_configuration(rng, family, i, fmu, values)
            if config is None:
                notes.append(f"{family.name} #{i}: no start of {F.ATTEMPTS} drawn gives a steady motion with a "
                             f"period in {F.PERIOD_RANGE[0]:g}-{F.PERIOD_RANGE[1]:g} s; not run")
                continue
            sigma = round(float(rng.uniform(*NOISE)), 6)
            seed = int(rng.integers(1, 2**31 - 1))
            faults = {}
            for test, group, size in (("length", lengths, LENGTH_STEP), ("mass", masses, MASS_STEP)):
                if group:
                    variable = str(rng.choice(group))
                    relative = size * float(rng.choice((1.0, -1.0)))
                    t = C.on_grid(float(rng.uniform(*FAULT_TIMES)), STEP)
                    faults[test] = C.Fault(variable=variable, relative=relative, time=t, before=values[variable])
            points = ",".join(c for c in F.outputs(family) if c[:1] in "xy" and c[1:].isdigit())
            settings = [(0.0, family.signal)] + ([(sigma, family.signal), (sigma, points)] if noisy else [])
            for noise_std, signal in settings:
                for test in tests:
                    fault = faults.get(test)
                    if test != "healthy" and fault is None:
                        continue
                    stop = healthy if fault is None else C.on_grid(fault.time + AFTER_FAULT, STEP)
                    name = f"{family.name}-{i:03d}"
                    text = _user_case_text(family, config, fmu, name=name, stop=stop)
                    payload = {"schema": ROW_SCHEMA, "family": family.name, "mechanism": F._digest(family.path),
                               "start": [config.theta, config.omega], "noise": [noise_std, seed],
                               "fault": None if fault is None else [fault.variable, fault.value, fault.time],
                               "stop": stop, "model": model, "signal": signal}
                    out_plan.append(Planned(key=_hash(payload), family=family.name, config_index=i, config=None,
                                            noise_std=noise_std, noise_seed=seed, test=test, fault=fault, stop=stop,
                                            signal=signal, text=text, period=config.period))
    return out_plan, notes


def _user_case_text(family, config, fmu: Path, *, name: str, stop: float) -> str:
    import mechanism_families as F

    theta_name, omega_name = family.independent
    return "\n".join([f"name = {json.dumps(name)}", f"description = {json.dumps(config.describe())}",
                      f"fmu = {json.dumps(str(fmu))}", "", "[experiment]", f"stop = {stop!r}", f"step = {STEP!r}",
                      "", "[parameters]", f"{theta_name} = {config.theta!r}", f"{omega_name} = {config.omega!r}",
                      "", "[outputs]", f"variables = {json.dumps(list(F.outputs(family)))}", ""])


def _scenario(p: Planned, model: str):
    from sweep.plan import Scenario

    f = p.fault
    return Scenario(id=p.key, index=0, variable=None if f is None else f.variable,
                    kind="none" if f is None else "step", relative_change=0.0 if f is None else f.relative,
                    fault_value=None if f is None else f.value, base_value=None if f is None else f.before,
                    fault_time=None if f is None else f.time, ramp_duration=None, noise_std=p.noise_std,
                    noise_seed=p.noise_seed if p.noise_std > 0 else None, signal=p.signal, model=model,
                    threshold="auto", stop=p.stop)


def _base_case(p: Planned, cases: Path):
    """The configuration's case file (every parameter named), loaded with the scenario's stop."""
    from orchestrator import apply_overrides, load_case

    path = cases / f"{p.family}-{p.config_index:03d}.toml"
    text = p.text if p.text is not None else C.case_text(p.config, NATIVE, stop=p.stop, step=STEP, name=path.stem)
    if not path.exists() or path.read_text() != text:
        path.write_text(text)
    return apply_overrides(load_case(path), stop=p.stop)


def run(planned: list[Planned], out: Path, *, model: str, workers: int | None, limit: int | None,
        fingerprint: str) -> dict[str, dict]:
    """Run what is not cached; return every row (cached and new) by key."""
    from dask.distributed import as_completed

    from sweep.runner import open_client
    from sweep.scenario import failed_row, run_scenario

    rows_dir, runs, cases = out / "rows", out / "runs", out / "cases"
    for d in (rows_dir, runs, cases):
        d.mkdir(parents=True, exist_ok=True)
    rows: dict[str, dict] = {}
    pending: list[Planned] = []
    stale = 0
    for p in planned:
        path = rows_dir / f"{p.key}.json"
        try:
            row = json.loads(path.read_text())
        except (OSError, ValueError):
            row = None
        if row is not None and row.get("code") == fingerprint:
            rows[p.key] = row
        else:
            stale += row is not None
            pending.append(p)
    if limit is not None:
        pending = pending[:max(0, limit)]
    print(f"robustness: {len(planned)} scenarios, {len(rows)} cached, {stale} measured on other code, "
          f"{len(pending)} to run now", file=sys.stderr, flush=True)
    if not pending:
        return rows
    t0 = time.perf_counter()
    import warnings

    # a second cluster on the machine takes another dashboard port: nothing to warn about
    warnings.filterwarnings("ignore", message="Port .* is already in use")
    with open_client(None, workers) as client:
        futures = {}
        for i, p in enumerate(pending):
            fut = client.submit(run_scenario, _scenario(p, model), _base_case(p, cases), str(runs / p.key), {},
                                keep_exchange=False, diagnose=True, pure=False, priority=len(pending) - i,
                                key=f"robustness-{p.key}-{os.urandom(4).hex()}")
            futures[fut] = p
        done = 0
        try:
            for fut in as_completed(list(futures)):
                p = futures.pop(fut)
                try:
                    row = fut.result()
                except Exception as exc:         # the worker died or the task was cancelled
                    row = failed_row(_scenario(p, model), f"worker: {type(exc).__name__}: {exc}")
                row.update(code=fingerprint, family=p.family, config_index=p.config_index, test=p.test,
                           motion_period=p.period if p.config is None else p.config.motion.period,
                           grashof=None if p.config is None else p.config.grashof)
                (rows_dir / f"{p.key}.json").write_text(json.dumps(row, default=str))
                rows[p.key] = row
                done += 1
                elapsed = time.perf_counter() - t0
                eta = elapsed / done * (len(pending) - done)
                status = row["status"] if row["status"] != "ok" else (
                    "alarm" if row.get("alarms") else "no alarm")
                print(f"  [{done}/{len(pending)}] {p.family} #{p.config_index} {p.test} σ={p.noise_std * 1000:g} mm: "
                      f"{status}; {elapsed:.0f} s, about {eta / 60:.1f} min left", file=sys.stderr, flush=True)
                fut.release()
        finally:
            if futures:
                client.cancel(list(futures))
    return rows


# ------------------------------------------------------------------------------------ report

def _fmt_s(x) -> str:
    return "–" if x is None else f"{x:.2f} s"


def _pct(n: int, d: int) -> str:
    return "–" if not d else f"{n}/{d} ({100 * n / d:.0f} %)"


def _monitored_seconds(row: dict) -> float:
    """Healthy monitored time of a run: after training, up to the fault (or the end)."""
    end = row["fault_time"] if row.get("fault_time") is not None else row["stop"]
    return max(0.0, float(end) - TRAIN_END)


@dataclass(frozen=True)
class Delays:
    runs: int
    detected: list[float]          # latencies of the detected faults, s
    missed: int
    after_false_alarm: int         # fault runs whose alarm came before the fault

    def cell(self) -> str:
        if not self.runs:
            return "–"
        parts = [f"{statistics.median(self.detected):.2f} / {max(self.detected):.2f} s"] if self.detected else []
        if self.missed:
            parts.append(f"missed {self.missed}")
        if self.after_false_alarm:
            parts.append(f"{self.after_false_alarm} alarmed before the fault")
        return ", ".join(parts)


def _delays(rows: list[dict]) -> Delays:
    """Latency of the runs that alarmed first after the fault; runs with no alarm after it
    (missed) and runs whose first alarm came before it, counted apart."""
    ok = [r for r in rows if r["status"] == "ok"]
    early = [r for r in ok if r.get("false_alarms")]
    lat = [float(r["latency"]) for r in ok if r.get("detected") and r not in early]
    return Delays(runs=len(ok), detected=lat, missed=sum(1 for r in ok if not r.get("detected") and r not in early),
                  after_false_alarm=len(early))


def _diagnosis(rows: list[dict]) -> tuple[int, int, list[float], list[float], dict[str, int]]:
    """Among the detected faults: right parameter (explained and named), value and time errors of
    the right ones, and what the wrong ones named."""
    detected = [r for r in rows if r["status"] == "ok" and r.get("detected")]
    right = [r for r in detected if r.get("diagnosis") == "explained" and r.get("diagnosed_variable") == r["variable"]]
    value_err = [abs(float(r["diagnosed_value"]) / float(r["fault_value"]) - 1.0) for r in right]
    time_err = [abs(float(r["diagnosed_time"]) - float(r["fault_time"])) for r in right]
    wrong: dict[str, int] = {}
    for r in detected:
        if r not in right:
            named = r.get("diagnosis") or "none"
            if named == "explained":
                named = f"{r['variable']} named {r.get('diagnosed_variable')}"
            elif named == "ambiguous" and r.get("diagnosed_runner_up"):
                named = (f"{r['variable']}: ambiguous, {r.get('diagnosed_variable')} or "
                         f"{r.get('diagnosed_runner_up')}")
            elif not str(named).startswith("failed"):
                named = f"{r['variable']}: {named}"
            wrong[named] = wrong.get(named, 0) + 1
    return len(right), len(detected), value_err, time_err, wrong


def report(rows: list[dict], *, planned: int, notes: list[str], args, wall: float, fingerprint: str) -> str:
    groups = [(f, noisy) for f in C.FAMILIES for noisy in (False, True)]

    def sel(family, noisy, test=None):
        return [r for r in rows if r["family"] == family and (r["noise_std"] > 0) == noisy
                and (test is None or r["test"] == test)]

    configs = {(r["family"], r["config_index"], r["noise_std"]) for r in rows}
    healthy_s = sum(_monitored_seconds(r) for r in rows if r["status"] == "ok")
    lines = [
        "# Robustness beyond Table 1", "",
        f"Generated by `python benchmarks/robustness.py{' --quick' if args.quick else ''} "
        f"--write docs/robustness.md` (do not edit by hand): {len(configs)} configurations "
        f"({args.per_family} per family, each "
        f"{'noise-free' if args.quick else f'noise-free and with σ = {NOISE[0] * 1000:g}–{NOISE[1] * 1000:g} mm on x2'}), "
        f"{len(rows)} of {planned} planned runs, native FMU, monitor `--model {args.model}` with the CUSUM at its "
        f"default setting, `fourbar-diagnose` after every alarm. Configurations from "
        f"`fmu_src/fourbar_configurations.py` (seed {SEED}; rules in its docstring). "
        f"Code fingerprint {fingerprint}; {wall / 60:.1f} min wall time this call.",
        "",
        "Runs per configuration: a healthy run of "
        f"{args.healthy:g} s; a {LENGTH_STEP:.0%} step of one length (L1–L4) and a {MASS_STEP:.0%} step of one "
        f"mass (m2–m4), each of either sign at a grid time in {FAULT_TIMES[0]:g}–{FAULT_TIMES[1]:g} s, running "
        f"{AFTER_FAULT:g} s past it. Healthy operation counts the monitored time after the 0–{TRAIN_END:g} s "
        f"training up to the fault (or the end): {healthy_s / 3600:.1f} h in all.", "",
    ]
    if args.quick:
        lines += ["**Quick setting (a smoke test of the chain): one noise-free configuration per family, short "
                  "healthy runs, no mass steps, the harmonic model. These figures mean nothing.**", ""]
    lines += [
        "## Per family", "",
        "False alarms: alarms at or before the fault time (every alarm of a healthy run), per hour of healthy "
        "monitoring. Delay: first alarm after the fault minus the fault time, median / max over the detected "
        "runs; missed: no alarm after the fault; a run that alarmed before its fault is counted apart. Diagnosis: the "
        "diagnosis names the stepped parameter and calls it explained, over the detected faults; value error "
        "relative to the new value, time error of the change time (median / max over the right ones).", "",
        "| family | noise | configs | healthy h | false alarms (per h) | largest statistic/limit, healthy "
        "| 1 % length step delay | 10 % mass step delay | right parameter | value error | time error |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for family, noisy in groups:
        g = sel(family, noisy)
        if not g:
            continue
        ok = [r for r in g if r["status"] == "ok"]
        hours = sum(_monitored_seconds(r) for r in ok) / 3600
        fa = sum(int(r.get("false_alarms") or 0) for r in ok)
        ratios = [float(r["statistic_max_pre"]) / float(r["threshold_base"]) for r in ok
                  if r.get("statistic_max_pre") is not None and r.get("threshold_base")]
        n_cfg = len({r["config_index"] for r in g})
        length, mass = _delays(sel(family, noisy, "length")), _delays(sel(family, noisy, "mass"))
        right, detected, verr, terr, _w = _diagnosis([r for r in g if r["test"] != "healthy"])
        noise = f"σ = {NOISE[0] * 1000:g}–{NOISE[1] * 1000:g} mm" if noisy else "none"
        lines.append(
            f"| {family} | {noise} | {n_cfg} | {hours:.2f} | {fa} ({fa / hours if hours else math.nan:.2g}) | "
            f"{max(ratios) if ratios else math.nan:.2f} | {length.cell()} | {mass.cell()} | {_pct(right, detected)} | "
            f"{_median_max(verr, pct=True)} | {_median_max(terr)} |")
    failed = [r for r in rows if r["status"] != "ok"]
    lines += ["", "## Runs that did not complete", ""]
    if failed:
        lines += ["| family | test | error |", "|---|---|---|"]
        lines += [f"| {r['family']} | {r['test']} | {str(r['error'])[:200]} |" for r in failed]
    else:
        lines.append("None: every run finished, was monitored, and every alarm was diagnosed.")
    lines += ["", "## Wrong or missing diagnoses", ""]
    _r, _d, _v, _t, wrong = _diagnosis([r for r in rows if r["test"] != "healthy"])
    if wrong:
        lines += ["| what happened | runs |", "|---|---:|"] + [f"| {k} | {v} |" for k, v in sorted(wrong.items())]
    else:
        lines.append("None: every detected fault was named right.")
    fa_rows = [r for r in rows if r["status"] == "ok" and r.get("false_alarms")]
    lines += ["", "## False alarms", ""]
    if fa_rows:
        lines += ["| family | test | noise | first alarm | fault time | period |", "|---|---|---|---:|---:|---:|"]
        lines += [f"| {r['family']} #{r['config_index']} | {r['test']} | {r['noise_std'] * 1000:g} mm | "
                  f"{_fmt_s(r.get('first_alarm_time'))} | {_fmt_s(r.get('fault_time'))} | "
                  f"{_fmt_s(r.get('motion_period'))} |" for r in fa_rows]
    else:
        lines.append("None.")
    lines += ["", "## The sample", "",
              "| family | configurations | Grashof | period range |", "|---|---:|---:|---:|"]
    for family in C.FAMILIES:
        g = [r for r in rows if r["family"] == family and r["test"] == "healthy" and r["noise_std"] == 0]
        if g:
            periods = [float(r["motion_period"]) for r in g]
            lines.append(f"| {family} | {len(g)} | {sum(bool(r['grashof']) for r in g)} | "
                         f"{min(periods):.2f}–{max(periods):.2f} s |")
    if notes:
        lines += ["", "Not run:", ""] + [f"- {n}" for n in notes]
    return "\n".join(lines) + "\n"


def _ambiguous_naming(row: dict) -> bool:
    """An ``ambiguous`` diagnosis one of whose two candidates is the stepped parameter."""
    return row.get("diagnosis") == "ambiguous" and row["variable"] in (row.get("diagnosed_variable"),
                                                                     row.get("diagnosed_runner_up"))


def report_user(rows: list[dict], *, planned: int, notes: list[str], args, wall: float, fingerprint: str) -> str:
    """The page's part on the user-style families (from USER_PART on)."""
    import mechanism_families as F

    def sel(family, setting, test=None):
        return [r for r in rows if r["family"] == family and _setting(r) == setting
                and (test is None or r["test"] == test)]

    configs = {(r["family"], r["config_index"]) for r in rows}
    sigma = f"σ = {NOISE[0] * 1000:g}–{NOISE[1] * 1000:g} mm"
    label = {"none": "none", "one": f"{sigma} on x2", "points": f"{sigma} on every point, all monitored"}
    lines = [
        USER_PART.strip(), "",
        f"Generated by `python benchmarks/robustness.py --mechanisms{' --quick' if args.quick else ''} "
        f"--per-family {args.per_family} --write docs/robustness.md` (do not edit by hand; it replaces only this "
        f"part): mechanism files users write, not Table 1's four-bar (`benchmarks/mechanism_families.py`: each "
        f"file, its start ranges and why its motions have no dead point). {len(configs)} configurations, "
        f"{len(rows)} of {planned} planned runs, native FMU, monitor `--model {args.model}`, `fourbar-diagnose` "
        f"after every alarm. Each configuration is a start drawn (seed {SEED}) and kept when a "
        f"{F.PRE_RUN:g} s healthy pre-run repeats with a period of {F.PERIOD_RANGE[0]:g}–{F.PERIOD_RANGE[1]:g} s; "
        f"then a healthy run of {args.healthy:g} s, a {LENGTH_STEP:.0%} step of one of its lengths and a "
        f"{MASS_STEP:.0%} step of one of its masses (drawn, either sign, at a grid time in "
        f"{FAULT_TIMES[0]:g}–{FAULT_TIMES[1]:g} s, running {AFTER_FAULT:g} s past it), each noise-free with x2 "
        f"monitored" + ("." if args.quick else
                        f"; with {sigma} on x2, x2 monitored (one sensor); and with the same σ on every point's x "
                        f"and y column the file records, all of them monitored (a sensor on every point: the "
                        f"diagnosis fits the monitored columns).")
        + f" Code fingerprint {fingerprint}; {wall / 60:.1f} min wall time this call.", "",
    ]
    if args.quick:
        lines += ["**Quick setting (a smoke test of the chain): these figures mean nothing.**", ""]
    lines += [
        "Columns as in the four-bar table above. Right parameter: the diagnosis names the stepped parameter and "
        "calls it explained. Ambiguous, naming it: the verdict is `ambiguous` (two parameters fit within its "
        "stated factor, docs/diagnose.md) and one of the two is the stepped parameter. Wrong: explained, but "
        "another parameter named; or ambiguous between two others; or unexplained.", "",
        "| family | mechanism | noise | configs | healthy h | false alarms (per h) | 1 % length step delay "
        "| 10 % mass step delay | right parameter | ambiguous, naming it | wrong | value error | time error |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for family in F.FAMILIES:
        for setting in label:
            g = sel(family.name, setting)
            if not g:
                continue
            ok = [r for r in g if r["status"] == "ok"]
            hours = sum(_monitored_seconds(r) for r in ok) / 3600
            fa = sum(int(r.get("false_alarms") or 0) for r in ok)
            length, mass = _delays(sel(family.name, setting, "length")), _delays(sel(family.name, setting, "mass"))
            faulted = [r for r in g if r["test"] != "healthy"]
            right, detected, verr, terr, _w = _diagnosis(faulted)
            named = sum(1 for r in faulted if r["status"] == "ok" and r.get("detected") and _ambiguous_naming(r))
            lines.append(
                f"| {family.name} | `{family.file}` | {label[setting]} | {len({r['config_index'] for r in g})} | {hours:.2f} | "
                f"{fa} ({fa / hours if hours else math.nan:.2g}) | {length.cell()} | {mass.cell()} | "
                f"{_pct(right, detected)} | {_pct(named, detected)} | {_pct(detected - right - named, detected)} | "
                f"{_median_max(verr, pct=True)} | {_median_max(terr)} |")
    failed = [r for r in rows if r["status"] != "ok"]
    lines += ["", "### Runs that did not complete", ""]
    lines += (["| family | test | error |", "|---|---|---|"]
              + [f"| {r['family']} #{r['config_index']} | {r['test']} | {str(r['error'])[:200]} |" for r in failed]
              if failed else ["None."])
    lines += ["", "### Totals", "",
              "| noise | healthy h | false alarms | detected faults | right parameter | ambiguous, naming it | wrong |",
              "|---|---:|---:|---:|---:|---:|---:|"]
    for setting in label:
        g = [r for r in rows if _setting(r) == setting]
        if not g:
            continue
        ok = [r for r in g if r["status"] == "ok"]
        faulted = [r for r in g if r["test"] != "healthy"]
        right, detected, _v, _t, _w = _diagnosis(faulted)
        named = sum(1 for r in faulted if r["status"] == "ok" and r.get("detected") and _ambiguous_naming(r))
        lines.append(f"| {label[setting]} | {sum(_monitored_seconds(r) for r in ok) / 3600:.2f} | "
                     f"{sum(int(r.get('false_alarms') or 0) for r in ok)} | {detected} | {_pct(right, detected)} | "
                     f"{_pct(named, detected)} | {_pct(detected - right - named, detected)} |")
    lines += ["", "### Wrong, ambiguous or missing diagnoses", ""]
    wrong_rows = []
    for setting in label:
        _r, _d, _v, _t, wrong = _diagnosis([r for r in rows if r["test"] != "healthy" and _setting(r) == setting])
        wrong_rows += [f"| {label[setting]} | {k} | {v} |" for k, v in sorted(wrong.items())]
    lines += (["| noise | what happened | runs |", "|---|---|---:|"] + wrong_rows
              if wrong_rows else ["None: every detected fault was named right."])
    fa_rows = [r for r in rows if r["status"] == "ok" and r.get("false_alarms")]
    lines += ["", "### False alarms", ""]
    lines += (["| family | test | noise | monitored | first alarm | fault time | period |",
               "|---|---|---|---|---:|---:|---:|"]
              + [f"| {r['family']} #{r['config_index']} | {r['test']} | {r['noise_std'] * 1000:g} mm | {r['signal']} | "
                 f"{_fmt_s(r.get('first_alarm_time'))} | {_fmt_s(r.get('fault_time'))} | "
                 f"{_fmt_s(r.get('motion_period'))} |" for r in fa_rows] if fa_rows else ["None."])
    if notes:
        lines += ["", "Not run:", ""] + [f"- {n}" for n in notes]
    return "\n".join(lines) + "\n"


def _setting(row: dict) -> str:
    """A user-style row's noise setting: ``none``, ``one`` (σ on the one monitored column) or
    ``points`` (σ on every point column, all monitored)."""
    if not row["noise_std"] > 0:
        return "none"
    return "points" if "," in str(row.get("signal") or "") else "one"


def _median_max(values: list[float], pct: bool = False) -> str:
    if not values:
        return "–"
    med, top = statistics.median(values), max(values)
    return f"{100 * med:.2g} / {100 * top:.2g} %" if pct else f"{med:.3f} / {top:.3f} s"


def _interrupt(signum, frame):
    raise KeyboardInterrupt



def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(REPO / "out" / "benchmarks" / "robustness"), help="cache and run folders")
    ap.add_argument("--write", metavar="FILE", help="write the Markdown page here (else stdout)")
    ap.add_argument("--per-family", type=int, default=34, help="configurations per family (default 34: 204 in all)")
    ap.add_argument("--healthy", type=float, default=300.0, help="s, length of the healthy runs (default 300)")
    ap.add_argument("--model", choices=("prophet", "harmonic"), default="prophet")
    ap.add_argument("--workers", type=int, default=None, help="Dask worker processes (default one per core)")
    ap.add_argument("--limit", type=int, default=None, help="run at most N scenarios now (the rest later)")
    ap.add_argument("--quick", action="store_true",
                    help="smoke test: 1 noise-free configuration per family, 30 s, length step, harmonic")
    ap.add_argument("--mechanisms", action="store_true",
                    help="the user-style mechanism families (benchmarks/mechanism_families.py) instead of the "
                         "four-bar's; --write then replaces only their part of the page")
    args = ap.parse_args(argv)
    if args.quick:
        args.per_family, args.healthy, args.model = 1, 30.0, "harmonic"
    if args.per_family < 1 or not args.healthy > TRAIN_END + 1:
        ap.error(f"--per-family must be >= 1 and --healthy above {TRAIN_END + 1:g} s")
    if not NATIVE.exists():
        print(f"robustness: {NATIVE} is missing: build it with `python build_fmu.py`", file=sys.stderr)
        return 2
    out = Path(args.out)
    t0 = time.perf_counter()
    signal.signal(signal.SIGTERM, _interrupt)          # stopped like Ctrl-C: finished rows are kept
    tests = ("healthy", "length") if args.quick else ("healthy", "length", "mass")
    if args.mechanisms:
        planned, notes = plan_user(args.per_family, args.healthy, args.model, out / "mechanisms",
                                   noisy=not args.quick, tests=tests)
        fingerprint = code_fingerprint(*sorted((out / "mechanisms" / "fmus").glob("*.fmu")))
    else:
        planned, notes = plan(args.per_family, args.healthy, args.model, noisy=not args.quick, tests=tests)
        fingerprint = code_fingerprint(NATIVE)
    try:
        rows = run(planned, out, model=args.model, workers=args.workers, limit=args.limit, fingerprint=fingerprint)
    except KeyboardInterrupt:
        print("robustness: interrupted; finished rows are kept, run the same command again to resume",
              file=sys.stderr)
        return 130
    keys = [p.key for p in planned if p.key in rows]
    text = (report_user if args.mechanisms else report)([rows[k] for k in keys], planned=len(planned), notes=notes,
                                                          args=args, wall=time.perf_counter() - t0,
                                                          fingerprint=fingerprint)
    if len(keys) < len(planned):
        print(f"robustness: {len(planned) - len(keys)} scenarios still to run (--limit); the page covers "
              f"{len(keys)}", file=sys.stderr)
    if args.write and args.mechanisms:
        write_part(Path(args.write), "user", text)
        print(f"wrote the user-style mechanisms' part of {args.write}", file=sys.stderr)
    elif args.write:
        write_part(Path(args.write), "four-bar", text)
        print(f"wrote {args.write}", file=sys.stderr)
    else:
        print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
