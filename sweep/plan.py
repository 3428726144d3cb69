"""From a sweep to its scenarios: the grid crossed with the random draws, each with a stable id.

Order of the axes (the order of the grid's nested loops, outermost first, and the order
in which one random draw takes its numbers)::

    fault.variable, fault.kind, fault size, fault.time, fault.ramp_duration, noise.std,
    noise.seed, monitor.model, monitor.threshold

Grid axes (values and arrays) are crossed; with ``[sample]`` there are ``n`` draws, each
taking one number per range axis from ``numpy.random.default_rng(seed)`` in that order, and
every grid point is combined with every draw (so all grid points see the same draws).
A drawn fault time or ramp duration is rounded to the case's communication grid.

Scenarios are then made canonical, so that runs which would be identical are run once:
a step has no ramp duration, a fault-free scenario has no fault time, size or kind
(``"none"``) and no variable (it is shared by every variable of the sweep), and a
noise-free one (std 0) no noise seed.  The scenario id is the first 16
hex digits of the SHA-256 of the canonical inputs -- the base case's parameters,
experiment and outputs, the fault, the noise, every monitor option -- as sorted JSON;
the FMU file is not part of it (its GUID is recorded in each result row instead).
"""
from __future__ import annotations

import hashlib
import itertools
import json
import math
from dataclasses import asdict, dataclass
from typing import Any

from .config import Range, Sweep

__all__ = ["ID_SCHEMA", "Scenario", "plan_scenarios", "threshold_text"]

#: Bump when the meaning of a scenario's inputs changes (invalidates stored results).
#: 2: a fault-free scenario names no variable (the variable became an axis).
ID_SCHEMA = 2


def threshold_text(threshold: float | str) -> str:
    """``"auto"`` or the number as ``repr`` (the form used in the table and in ids)."""
    return threshold if isinstance(threshold, str) else repr(float(threshold))


@dataclass(frozen=True)
class Scenario:
    """The inputs of one scenario (canonical; see the module docstring)."""

    id: str
    index: int                   # position in the sweep's plan
    variable: str | None         # the changed parameter; None without a fault
    kind: str                    # "step" | "ramp" | "none"
    relative_change: float       # (fault_value - base_value)/base_value; 0 without a fault
    fault_value: float | None    # the variable's value after the fault (end of a ramp), its unit
    base_value: float | None     # the variable's value in the base case; None without a fault
    fault_time: float | None     # s: a step's time or a ramp's start
    ramp_duration: float | None  # s
    noise_std: float             # the monitored signal's unit
    noise_seed: int | None
    signal: str
    model: str
    threshold: str               # "auto" or a number as text
    stop: float                  # s

    @property
    def has_fault(self) -> bool:
        return self.kind != "none"

    @property
    def threshold_value(self) -> float | str:
        return self.threshold if self.threshold == "auto" else float(self.threshold)

    def inputs(self) -> dict[str, Any]:
        """The scenario's columns of the results table."""
        d = asdict(self)
        d["scenario_id"] = d.pop("id")
        d["has_fault"] = self.has_fault
        return d


def _grid_round(t: float, start: float, step: float) -> float:
    return start + round((t - start) / step) * step


def _case_fingerprint(sweep: Sweep) -> dict[str, Any]:
    case = sweep.case
    return {"parameters": dict(sorted(case.parameters.items())),
            "experiment": case.experiment.as_dict(),
            "outputs": list(case.outputs)}


def _scenario_id(payload: dict[str, Any]) -> str:
    text = json.dumps(payload, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]


def plan_scenarios(sweep: Sweep) -> tuple[Scenario, ...]:
    """Every scenario of ``sweep``, in plan order, duplicates removed (first one kept)."""
    import numpy as np

    f, n, m = sweep.fault, sweep.noise, sweep.monitor
    exp = sweep.case.experiment
    axes = {"variable": f.variables, "kind": f.kind, "size": f.size, "time": f.time, "ramp_duration": f.ramp_duration or (None,),
            "std": n.std, "seed": n.seed, "model": m.model, "threshold": m.threshold}
    sampled = [name for name, axis in axes.items() if isinstance(axis, Range)]
    if sweep.sample is not None and sampled:
        rng = np.random.default_rng(sweep.sample.seed)
        draws = [{name: axes[name].draw(rng) for name in sampled} for _ in range(sweep.sample.n)]
    else:
        draws = [{}]
    grid_names = [name for name in axes if name not in sampled]
    fingerprint = _case_fingerprint(sweep)
    monitor_options = {k: (list(v) if isinstance(v, tuple) else v) for k, v in m.options.items()}

    def make(values: dict[str, Any], fault: bool) -> tuple[str, dict[str, Any]]:
        std = float(values["std"])
        seed = int(values["seed"]) if std > 0 else None
        if fault:
            kind, variable = values["kind"], values["variable"].name
            base = values["variable"].base_value
            if f.size_mode == "relative":
                relative = float(values["size"])
                value = base * (1.0 + relative)
            else:
                value = float(values["size"])
                relative = (value - base) / base if base != 0 else math.inf
            t = _grid_round(float(values["time"]), exp.start, exp.step)
            duration = None
            if kind == "ramp":
                duration = max(exp.step, round(float(values["ramp_duration"]) / exp.step) * exp.step)
        else:
            kind, variable, base, relative, value, t, duration = "none", None, None, 0.0, None, None, None
        threshold = threshold_text(values["threshold"])
        inputs = dict(variable=variable, kind=kind, relative_change=relative, fault_value=value,
                      base_value=base, fault_time=t, ramp_duration=duration, noise_std=std,
                      noise_seed=seed, signal=m.signal, model=values["model"], threshold=threshold,
                      stop=sweep.stop)
        payload = {"schema": ID_SCHEMA, "case": fingerprint, "monitor": monitor_options,
                   **{k: v for k, v in inputs.items() if k != "relative_change"}}
        return _scenario_id(payload), inputs

    planned: dict[str, dict[str, Any]] = {}
    for combo in itertools.product(*(axes[name] for name in grid_names)):
        grid_values = dict(zip(grid_names, combo))
        for draw in draws:
            sid, inputs = make({**grid_values, **draw}, fault=True)
            planned.setdefault(sid, inputs)
    if f.no_fault:
        clean_names = [name for name in ("std", "seed", "model", "threshold") if name in grid_names]
        for combo in itertools.product(*(axes[name] for name in clean_names)):
            grid_values = dict(zip(clean_names, combo))
            for draw in draws:
                sid, inputs = make({**grid_values, **draw}, fault=False)
                planned.setdefault(sid, inputs)
    return tuple(Scenario(id=sid, index=i, **inputs) for i, (sid, inputs) in enumerate(planned.items()))
