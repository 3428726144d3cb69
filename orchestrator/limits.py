"""What a case may ask of a run: the bounds beyond which a value cannot be meant.

Validation (:mod:`orchestrator.config`) refuses a case that exceeds one of these with the
file, field and value named (exit 2), before anything is loaded or written; ``--set``,
``--stop`` and ``--fmu`` go through the same checks.

Communication step.  One ``doStep`` is one uninterruptible foreign call: the FMU integrates
the whole step before it returns.  ``fourbar-run`` stays responsive to signals during it
(:mod:`orchestrator.stepping`), but a step of days still means a run whose first row after
``start`` comes days later.  So a step is at most :data:`MAX_STEP` s (and at most the run's
span, which the grid check already demands: at least one whole step).  10 s is a hundred
periods of the shipped mechanisms' free motion (0.1-3 s) and ten times the coarsest step a
monitor can use for a 1 s period; combined with ``exchange.max_rows`` (10,000,000 rows by
default) it also bounds a run's span (1e8 s).

Real-time pace.  ``exchange.realtime_factor`` (``--realtime``) is 0 or at least
:data:`MIN_REALTIME_FACTOR`.

Rates and angles.  A start value of a Real parameter is bounded by its declared unit
(:data:`UNIT_LIMITS`): no linkage turns at 1e15 rad/s (its integrator would then take
billions of steps per communication step).  The limits are far above anything physical, so
they refuse only typing slips and fuzz, never a design:

- ``rad/s``: 1e4 rad/s (95,000 rpm; a Formula 1 engine's crank turns at about 2,000 rad/s);
- ``deg/s``: the same rate in degrees;
- ``m/s``: 1e3 m/s (a rifle bullet; a slider's speed is a crank rate times a length);
- ``rad``: 1e6 rad (160,000 turns; beyond it a double keeps fewer than 10 digits of the
  angle within one turn); ``deg``: the same angle in degrees.
"""
from __future__ import annotations

import math

__all__ = ["MAX_STEP", "MIN_REALTIME_FACTOR", "UNIT_LIMITS"]

#: s: the longest communication step (one doStep) a case may ask for.
MAX_STEP = 10.0

#: The slowest real-time pace: 0 (as fast as possible) or at least this factor.  At 1e-3 a
#: 100 s case already lasts 28 hours of wall time; 1e-300 (accepted before) meant forever.
MIN_REALTIME_FACTOR = 1e-3

_DEG = 180.0 / math.pi
#: Declared unit of a Real parameter -> largest magnitude of a start value or event value.
UNIT_LIMITS: dict[str, float] = {
    "rad/s": 1e4,
    "deg/s": 1e4 * _DEG,
    "m/s": 1e3,
    "rad": 1e6,
    "deg": 1e6 * _DEG,
}
