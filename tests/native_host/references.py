"""What tests/test_fmu_native.py compares the generic native FMU with.

- :func:`build_today_native_fmu`: the four-bar's native FMU as it was before mechanisms became
  data (commit ``TODAY``: a closed-form loop closure, hand-shaped C), built from that commit's
  own sources (``git archive``, nothing in the working tree is touched) with its own build.
- :func:`python_run`: the pythonfmu FMU's run-time, ``MechanismDAE``, run in-process on the
  communication grid exactly as its slave drives it (parameters changed before the step that
  starts at the change time, times snapped to whole nanoseconds).
"""
from __future__ import annotations

import io
import shutil
import subprocess
import sys
import tarfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
#: The last commit whose native FMU was the hand-shaped four-bar (the commit before issue 24).
TODAY = "330a5a6c0b2bf4badd403b111ba0e864b1b7cb35"


class ReferenceUnavailable(RuntimeError):
    """The reference cannot be had here (no git, a shallow clone without TODAY...)."""


def build_today_native_fmu(work_dir: Path) -> Path:
    """FourBarNative.fmu of commit TODAY, built by that commit's fmu_src/native_build.py in
    ``work_dir``; raises ReferenceUnavailable when the commit cannot be read."""
    git = shutil.which("git")
    if git is None:
        raise ReferenceUnavailable("git is not installed")
    archive = subprocess.run([git, "-C", str(REPO), "archive", "--format=tar", TODAY], capture_output=True)
    if archive.returncode != 0:
        raise ReferenceUnavailable(f"git archive {TODAY[:7]} failed (a shallow clone?): "
                                   f"{archive.stderr.decode(errors='replace').strip()}")
    source = Path(work_dir) / "today"
    with tarfile.open(fileobj=io.BytesIO(archive.stdout)) as tar:
        tar.extractall(source, filter="data")
    dest = Path(work_dir) / "FourBarNative_today.fmu"
    code = "import sys; from fmu_src.native_build import build_native_fmu; build_native_fmu(sys.argv[1], validate=False)"
    subprocess.run([sys.executable, "-c", code, str(dest)], cwd=source, check=True, capture_output=True)
    return dest


@dataclass(frozen=True)
class PythonRun:
    """Outputs of MechanismDAE at the grid times 0, step, 2 step, ... (row 0: the start)."""

    time: np.ndarray
    values: dict[str, np.ndarray]
    repartitions: int

    def __getitem__(self, name: str) -> np.ndarray:
        return self.values[name]


def python_run(mechanism: str | Path, stop: float, tolerance: float, change: tuple[float, str, float] | None = None,
               step: float = 0.01, atol: float | None = None, method: str = "DOP853") -> PythonRun:
    """``mechanism`` (a shipped name or a file) integrated by MechanismDAE with ``method`` at rtol =
    ``tolerance`` and atol = ``atol`` (default: the same) for ``stop`` s; ``change = (time,
    parameter, value)`` is applied as the slave applies a value set at that grid point."""
    from fmu_src.mechanism.check import prepare_mechanism, start_state
    from fmu_src.mechanism_model.dae import MechanismDAE, snap_time

    eq = prepare_mechanism(str(mechanism)).module
    guess, rates, p = start_state(eq)
    dae = MechanismDAE(eq, p, method=method, rtol=tolerance, atol=tolerance if atol is None else atol,
                       t_bound=stop + 1.0)
    dae.assemble(0.0, guess, rates)
    dae.start()
    names = [v.name for v in eq.VARIABLES if v.causality == "output"]
    n = round(stop / step)
    rows = [dae.outputs()]
    for k in range(n):
        t = k * step
        if change is not None and abs(t - change[0]) < 0.5 * step:
            new = list(dae.p)
            new[eq.PARAMETERS.index(change[1])] = change[2]
            dae.change_parameters(new)
        dae.advance(snap_time((k + 1) * step))
        rows.append(dae.outputs())
    table = np.array(rows)
    return PythonRun(np.arange(n + 1) * step, {name: table[:, i] for i, name in enumerate(names)}, dae.repartitions)
