"""Does a fault mean the same at every crank phase?  (issue 37; the pythonfmu FMU's MechanismDAE, in-process)

1. The scan: the quick-return of tests/mechanisms, as written and at twice its size (where the
   partition review on the LU pivot ratio, before the velocity-ratio review, left theta2), its
   crank started at 3 rad/s; L4 +1 % at 40 fault times (every 0.5 s over 20 s): how many keep
   theta2 and omega2 exactly across the re-assembly, the changes of independent coordinates in the
   run and the largest velocity ratio of theta2 (dae.py's REPARTITION_AWAY).
2. The shipped cases (cases/*.toml), their first --seconds s with their parameters and events:
   the changes of independent coordinates and the largest velocity ratio of the declared ones.

    python benchmarks/fault_phase.py                      # this tree's dae.py
    git show c0cec05:fmu_src/mechanism_model/dae.py > /tmp/dae_before.py
    python benchmarks/fault_phase.py --dae /tmp/dae_before.py     # another dae.py, for a before/after
"""
from __future__ import annotations

import argparse
import copy
import importlib.util
import re
import sys
import tempfile
import time
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from fmu_src.mechanism.check import prepare_mechanism, start_state  # noqa: E402
from fmu_src.mechanism.description import load_mechanism, shipped_mechanisms  # noqa: E402
from fmu_src.mechanism_model import dae as this_dae  # noqa: E402

DOUBLED = ((r'^name = "QuickReturn"', 'name = "QuickReturnDoubled"'), (r"^d = \{ value = 1\.0,", "d = { value = 2.0,"),
           (r"^r = \{ value = 0\.5,", "r = { value = 1.0,"), (r"^L4 = \{ value = 2\.0,", "L4 = { value = 4.0,"),
           (r"^L5 = \{ value = 1\.0,", "L5 = { value = 2.0,"), (r"^H = \{ value = 2\.2,", "H = { value = 4.4,"),
           (r"^x = 0\.43$", "x = 0.86"), (r"^y = 1\.25$", "y = 2.5"), (r"^x = 1\.5$", "x = 3.0"),
           (r"^y = 2\.2$", "y = 4.4"))


def load_dae(path: str | None):
    if path is None:
        return this_dae
    spec = importlib.util.spec_from_file_location("dae_measured", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def doubled(folder: Path) -> Path:
    text = (REPO / "tests" / "mechanisms" / "quick_return.toml").read_text(encoding="utf-8")
    for pattern, new in DOUBLED:
        text, n = re.subn(pattern, new, text, flags=re.M)
        if n != 1:
            raise SystemExit(f"tests/mechanisms/quick_return.toml: no single line matching {pattern!r}")
    path = folder / "quick_return_doubled.toml"
    path.write_text(text, encoding="utf-8")
    return path


def _copy(dae, eq):
    c = copy.deepcopy(dae, {id(eq): eq})
    c._Jp_flat = c._Jp.reshape(-1, order="F")        # a dae.py without __setstate__ loses the view
    return c


def ratio_of(eq, q, p) -> float:
    """The velocity ratio of the declared coordinates (this tree's dae.py measures it)."""
    probe = this_dae.MechanismDAE(eq, p)
    probe._set_length_scale(this_dae.length_scale(eq.COORDINATES, q))
    return probe.velocity_ratio(eq.jacobian(q, p), tuple(eq.INDEPENDENT))


def scan(mod, path: Path, rate: float = 3.0, times: int = 40, every: float = 0.5) -> str:
    eq = prepare_mechanism(str(path)).module
    guess, rates, p = start_state(eq)
    rates[eq.INDEPENDENT[0]] = rate
    dae = mod.MechanismDAE(eq, p, rtol=1e-9, atol=1e-9)
    dae.assemble(0.0, guess, rates)
    dae.start()
    j = eq.PARAMETERS.index("L4")
    kept, worst, ratio = 0, 0.0, 0.0
    steps = round(every / 0.01)
    for k in range(1, times * steps + 1):
        dae.advance(mod.snap_time(k * 0.01))
        ratio = max(ratio, ratio_of(eq, dae.q, dae.p))
        if k % steps:
            continue
        c = _copy(dae, eq)
        before = [(c.q[i], c.qd[i]) for i in eq.INDEPENDENT]
        new = list(c.p)
        new[j] *= 1.01
        c.change_parameters(new)
        err = max(abs(a - b) for pair, i in zip(before, eq.INDEPENDENT) for a, b in zip(pair, (c.q[i], c.qd[i])))
        kept += err == 0.0
        worst = max(worst, err)
    return (f"{path.stem}: L4 +1 % at {times} fault times kept theta2, omega2 at {kept}; largest change "
            f"{worst:.3g}; {dae.repartitions} changes of independent coordinates in 20 s; largest velocity "
            f"ratio of theta2 {ratio:.3g}")


def case_run(mod, case: Path, seconds: float) -> str:
    spec = tomllib.loads(case.read_text(encoding="utf-8"))
    stem = Path(spec["fmu"]).stem
    names = {load_mechanism(m).name: m for m in shipped_mechanisms()}
    eq = prepare_mechanism(names[stem]).module
    starts = {v.name: v.start for v in eq.VARIABLES}
    starts.update(spec.get("parameters", {}))
    guess, rates = list(eq.GUESS), [0.0] * eq.N_COORDINATES
    for i, (a, b) in zip(eq.INDEPENDENT, eq.START_PARAMETERS):
        guess[i], rates[i] = float(starts[a]), float(starts[b])
    p = [float(starts[n]) for n in eq.PARAMETERS]
    dae = mod.MechanismDAE(eq, p, rtol=float(starts["rtol"]), atol=float(starts["atol"]))
    dae.assemble(0.0, guess, rates)
    dae.start()
    step, ratio = float(spec["experiment"]["step"]), 0.0
    for k in range(1, round(seconds / step) + 1):
        t = k * step
        new = list(dae.p)
        for event in spec.get("events", []):
            j = eq.PARAMETERS.index(event["variable"])
            if event["type"] == "step" and abs(event["time"] - (t - step)) < 1e-9:
                new[j] = float(event["value"])
            elif event["type"] == "ramp" and event["start"] <= t - step <= event["end"] + 1e-9:
                s = (t - step - event["start"]) / (event["end"] - event["start"])
                new[j] = event["from"] + s * (event["to"] - event["from"])
        if tuple(new) != tuple(dae.p):
            dae.change_parameters(new)
        dae.advance(mod.snap_time(t))
        if eq.INDEPENDENT:
            ratio = max(ratio, ratio_of(eq, dae.q, dae.p))
    return (f"{case.stem}: {dae.repartitions} changes of independent coordinates in {seconds:g} s; largest "
            f"velocity ratio of the declared coordinates {ratio:.3g}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dae", help="a dae.py to measure instead of this tree's (e.g. an earlier commit's)")
    parser.add_argument("--seconds", type=float, default=20.0, help="how much of each shipped case to run (s)")
    parser.add_argument("--no-cases", action="store_true", help="only the quick-return scan")
    args = parser.parse_args(argv)
    mod = load_dae(args.dae)
    print(f"dae.py: {args.dae or 'this tree'}")
    with tempfile.TemporaryDirectory() as folder:
        for path in (REPO / "tests" / "mechanisms" / "quick_return.toml", doubled(Path(folder))):
            start = time.perf_counter()
            print(scan(mod, path), f"({time.perf_counter() - start:.0f} s)", flush=True)
    if not args.no_cases:
        for case in sorted((REPO / "cases").glob("*.toml")):
            print(case_run(mod, case, args.seconds), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
