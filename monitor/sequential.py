"""The sequential detector's numerics: noise scale, CUSUM design, the residual engine and the latch.

For every monitored signal ``s`` the engine forms the phase-locked residual and its
standardised value::

    r_s(t) = x_s(t) − f_s(t − τ̂(t))             (f_s: the fitted forecast, periodic)
    z_s(t) = r_s(t) / sqrt(σ_s² + f_s'(t − τ̂)² · Var τ̂(t))

and runs a two-sided CUSUM (:mod:`monitor.cusum`) on each ``z_s``.  ``τ̂`` comes from one
:class:`~monitor.tracking.PhaseTracker` shared by the signals (one mechanism, one phase),
updated block by block (``block`` s) with data at least ``guard`` s old and only while the
detector is quiet, so a fault is not learnt before it is detected.

Noise scale (:func:`noise_scale`)
    ``σ_s`` is learnt from held-out training data: a model of the same kind fitted on the
    first 2/3 of the training window forecasts the rest.  The residuals there are
    autocorrelated when the model error dominates (the noise-free case) and white when
    sensor noise dominates.  Both are covered by the long-run standard deviation of an
    AR(1) fit, ``std · sqrt((1 + ρ)/(1 − ρ))`` (ρ, the lag-1 autocorrelation, clipped to
    [0, 0.95]): a CUSUM with a small reference ``k`` integrates many samples, so its
    in-control behaviour is set by the long-run variance.  The estimate is raised to its
    upper confidence limit ``(1 + c/sqrt(2·n_eff))`` (``c = 2``, ``n_eff = n(1 − ρ)/(1 + ρ)``)
    because the run length depends exponentially on the scale.  Finally a floor of
    ``noise_floor`` × the training amplitude applies: a noise-free simulation has almost no
    noise (a few µm of model error), and the floor stands for the smallest deviation worth
    an alarm; it also keeps the CUSUM blind to the model's µm-level periodic error.

Design (:func:`design_cusum`)
    ``k = δ/2`` for the design shift ``δ`` (in σ); ``h`` from the false-alarm rate per hour
    (see :mod:`monitor.cusum`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from .cusum import arl_siegmund, cusum_path, cusum_threshold
from .detector import Event, State, alarm_event
from .errors import OptionError
from .tracking import PeriodicTemplate, PhaseTracker, ShapeCorrection

__all__ = ["Crossing", "CusumDesign", "NoiseScale", "ResidualCusum", "SequentialDetector", "design_cusum",
           "noise_scale"]

#: z of the upper confidence limit put on the noise scale.
SCALE_CONFIDENCE = 2.0
#: Largest lag-1 autocorrelation used in the long-run scale.
MAX_LAG1 = 0.95
#: z of the phase-error bound: the scale is widened by ``f'·PHASE_Z·e`` for the phase error ``e`` seen.
PHASE_Z = 2.0
#: s of data: how long a phase error seen on healthy data keeps widening the scale (decay time).
PHASE_ERROR_MEMORY = 600.0
#: Samples without a crossing after which the statistics go back from the scalar to the vectorised pass.
SCALAR_RUN = 64


@dataclass(frozen=True)
class NoiseScale:
    """How a signal's residuals are standardised (units of the signal)."""

    held_out_std: float
    lag1: float
    long_run_std: float
    samples: int
    inflation: float
    floor: float
    sigma: float

    @property
    def at_floor(self) -> bool:
        return self.sigma <= self.floor

    def as_dict(self) -> dict[str, Any]:
        return {"held_out_std": self.held_out_std, "lag1": self.lag1, "long_run_std": self.long_run_std,
                "held_out_samples": self.samples, "inflation": self.inflation, "floor": self.floor,
                "sigma": self.sigma, "at_floor": self.at_floor}


def noise_scale(residual: np.ndarray, amplitude: float, floor_fraction: float) -> NoiseScale:
    """The standardisation scale from held-out residuals (rules in the module docstring)."""
    r = np.asarray(residual, dtype=float)
    r = r[np.isfinite(r)]
    n = int(r.size)
    std = float(np.sqrt(np.mean(r * r))) if n else 0.0
    lag1 = 0.0
    if n > 2:
        d = r - r.mean()
        denom = float(d @ d)
        if denom > 0:
            lag1 = float(np.clip((d[1:] @ d[:-1]) / denom, 0.0, MAX_LAG1))
    long_run = std * math.sqrt((1 + lag1) / (1 - lag1))
    n_eff = max(n * (1 - lag1) / (1 + lag1), 2.0)
    inflation = 1.0 + SCALE_CONFIDENCE / math.sqrt(2.0 * n_eff)
    floor = float(floor_fraction) * float(amplitude)
    return NoiseScale(std, lag1, long_run, n, inflation, floor, max(long_run * inflation, floor))


@dataclass(frozen=True)
class CusumDesign:
    """The CUSUM's reference ``k`` and limit ``h`` and what they were designed for."""

    false_alarm_rate: float        # per hour of data, all statistics together
    sample_step: float             # s
    statistics: int                # one-sided statistics (2 per signal)
    shift: float                   # design shift δ, in σ
    k: float
    h: float

    @property
    def arl0_samples(self) -> float:
        """In-control ARL of each one-sided statistic (Siegmund), in samples."""
        return arl_siegmund(self.h, self.k)

    @property
    def arl0_hours(self) -> float:
        """Bound on the mean time between false alarms of the whole detector (union bound)."""
        return self.arl0_samples * self.sample_step / self.statistics / 3600.0

    def limit_at_arl0(self, hours: float) -> float:
        """The limit ``h`` this design would have for a mean of ``hours`` between false alarms (same
        ``k``, sampling step and statistic count; Siegmund)."""
        return cusum_threshold(hours * 3600.0 * self.statistics / self.sample_step, self.k)

    def as_dict(self) -> dict[str, Any]:
        return {"rule": "two-sided CUSUM on standardised residuals", "false_alarm_rate_per_hour": self.false_alarm_rate,
                "sample_step_s": self.sample_step, "one_sided_statistics": self.statistics,
                "design_shift_sigma": self.shift, "k": self.k, "h": self.h,
                "arl0_samples_each": self.arl0_samples, "arl0_hours": self.arl0_hours}


def design_cusum(false_alarm_rate: float, sample_step: float, signals: int, shift: float) -> CusumDesign:
    """``k = shift/2`` and the ``h`` that keeps the false-alarm rate (per hour) of ``2·signals`` statistics."""
    statistics = 2 * int(signals)
    arl_each = statistics * 3600.0 / (float(false_alarm_rate) * float(sample_step))
    k = 0.5 * float(shift)
    return CusumDesign(float(false_alarm_rate), float(sample_step), statistics, float(shift), k,
                       cusum_threshold(arl_each, k))


@dataclass(frozen=True)
class Crossing:
    """A CUSUM statistic passed its limit: at ``time``, on ``signal``, side ``+`` or ``-``.

    ``onset`` is the CUSUM's estimate of when the change began: the last time that
    statistic was zero.
    """

    time: float
    signal: str
    side: str
    statistic: float
    threshold: float
    onset: float


class SequentialDetector:
    """Latched alarms for the sequential (CUSUM) detector: one alarm episode per fault.

    ``STABLE`` → ``ALARM`` at the first :class:`Crossing` (event ``alarm``; the statistics
    restart from zero).  The alarm latches: further crossings extend the episode.  It
    clears (event ``clear``, → ``STABLE``) at the first evaluation ``clear_after`` s after
    the episode's last crossing, i.e. after that long a stretch in which the restarted
    statistics stayed below their limit: a growing fault or a deviation seen once per cycle
    keeps re-crossing and never flaps.  ``events`` receives each event.
    """

    def __init__(self, *, clear_after: float, emit: Callable[[list[Event]], None]):
        if not (clear_after > 0):
            raise OptionError(f"clear_after: expected a positive number of seconds, got {clear_after!r}")
        self.clear_after = float(clear_after)
        self._emit = emit
        self.state = State.TRAINING
        self.alarms = 0
        self.first_alarm: Event | None = None
        self.crossings = 0
        self._last_crossing: float | None = None
        self._quiet_since = -np.inf

    def trained(self, time: float, threshold: float, info: dict[str, Any]) -> None:
        self.state = State.STABLE
        self._quiet_since = float(time)
        self._emit([Event(time, "trained", State.TRAINING, None, threshold, "model fitted", dict(info)),
                    Event(time, "stable", State.STABLE, None, threshold, "state 1: monitoring with the fitted model")])

    def crossing(self, c: Crossing) -> None:
        if self.extend(c.time):
            return
        self.crossings += 1
        self._last_crossing = c.time
        self.state = State.ALARM
        self.alarms += 1
        ev = alarm_event(c.time, c.statistic, c.threshold, reason="cusum", signal=c.signal, side=c.side,
                         onset=c.onset, episode=self.alarms)
        if self.first_alarm is None:
            self.first_alarm = ev
        self._emit([ev])

    def extend(self, time: float) -> bool:
        """A crossing at ``time`` while an alarm is latched: it only extends the episode (what
        :meth:`crossing` does then, without building a :class:`Crossing`).  False, and nothing
        done, when no alarm is latched: the caller reports the crossing in full."""
        if self.state is not State.ALARM:
            return False
        self.crossings += 1
        self._last_crossing = time
        return True

    def tick(self, time: float) -> None:
        """An evaluation time passed: clear a latched alarm after ``clear_after`` s without a crossing."""
        if self.state is State.ALARM and self._last_crossing is not None \
                and time - self._last_crossing >= self.clear_after - 1e-9:
            self.state = State.STABLE
            self._quiet_since = float(time)
            self._emit([Event(time, "clear", State.STABLE, None, None,
                              f"no CUSUM crossing for {self.clear_after:g} s: alarm episode {self.alarms} ended")])

    def quiet_since(self, time: float) -> bool:
        """True when there has been no alarm from ``time`` until now (data there are healthy)."""
        return self.state is State.STABLE and time >= self._quiet_since - 1e-9


@dataclass
class _Pending:
    """Residual rows kept for the tracker until their block is ``guard`` s old."""

    t: np.ndarray
    residual: np.ndarray            # (n, m)  x − forecast (template + correction)
    slope: np.ndarray               # (n, m)
    shift: np.ndarray               # (n,)
    correction: np.ndarray          # (n, m)  the shape correction in the forecast


class ResidualCusum:
    """Phase-locked residuals → CUSUM per signal → :class:`SequentialDetector`.

    ``feed(t, X)`` takes samples after ``origin`` (``X``: one column per signal) in any
    batch sizes; tracker updates happen at fixed data times (``origin + j·block + guard``)
    and evaluations are recorded at ``origin + j·every``, so the result does not depend on
    how the data were batched.  ``on_evaluation(time, statistic, threshold, state)``
    receives the largest statistic over each ``every`` interval.
    """

    def __init__(self, names: tuple[str, ...], templates: list[PeriodicTemplate], scales: list[NoiseScale],
                 design: CusumDesign, tracker: PhaseTracker, detector: SequentialDetector, *, origin: float,
                 guard: float, block: float, every: float, sample_step: float,
                 on_evaluation: Callable[[float, float, float, State], None],
                 corrections: list[ShapeCorrection] | None = None):
        self.names = names
        self.templates = templates
        self.corrections = corrections
        self._sigma2_noise = np.array([s.sigma ** 2 for s in scales])
        self.sigma2 = self._sigma2_noise.copy()
        #: s²: the decaying peak of the mean squared phase error the CUSUM was fed (see _learn_phase_error)
        self.phase_error2 = 0.0
        self._phase_error_time: float | None = None
        self.design = design
        self.tracker = tracker
        self.detector = detector
        self.origin = float(origin)
        self.guard = float(guard)
        self.block = float(block)
        self.every = float(every)
        self._eps = 1e-6 * float(sample_step)
        self.on_evaluation = on_evaluation
        m = len(names)
        self._s = np.zeros((2, m))                      # S⁺, S⁻ per signal
        self._zero_time = np.full((2, m), self.origin)  # last time each statistic was 0 (change-onset estimate)
        self._next_block = 1
        self._next_eval = 1
        self._eval_max = 0.0
        self._pending = _Pending(np.empty(0), np.empty((0, m)), np.empty((0, m)), np.empty(0), np.empty((0, m)))
        self.blocks_used = 0
        self.blocks_skipped = 0
        self.max_ratio = 0.0

    @property
    def pending_samples(self) -> int:
        return int(self._pending.t.size)

    # -- the forecast ------------------------------------------------------------------------
    def forecast(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Phase-locked forecast (shape correction included), slope, shift, shift variance and the
        correction at ``t`` (from the tracker's and the corrections' state)."""
        shift, var = self.tracker.shift(t)
        tt = np.asarray(t, dtype=float) - shift
        f = np.column_stack([tpl.value(tt) for tpl in self.templates])
        g = np.column_stack([tpl.slope(tt) for tpl in self.templates])
        if self.corrections is None:
            c = np.zeros_like(f)
        else:
            c = np.column_stack([corr.value(tt) for corr in self.corrections])
        return f + c, g, shift, var, c

    # -- feeding -----------------------------------------------------------------------------
    def feed(self, t: np.ndarray, X: np.ndarray) -> np.ndarray:
        """Process samples; returns the forecast of every signal at ``t`` (for the history)."""
        t = np.asarray(t, dtype=float)
        X = np.asarray(X, dtype=float).reshape(t.size, -1)
        out = np.empty_like(X)
        i = 0
        while i < t.size:
            boundary = self.origin + self._next_block * self.block + self.guard
            j = int(np.searchsorted(t, boundary + self._eps, side="right"))
            if j > i:
                out[i:j] = self._segment(t[i:j], X[i:j])
            if j < t.size:
                self._update_tracker()
            i = j
        return out

    def skip(self, start: float, end: float) -> None:
        """No samples in (``start``, ``end``): move the block and evaluation clocks past the gap.

        The pending samples (not yet confirmed healthy by ``guard`` s of later data) are
        dropped rather than learnt; evaluations and tracker blocks due inside the gap are
        not made; the statistics restart from zero after it (their onset estimate with them).
        The tracker's prediction runs on over the gap (its variance is capped).
        """
        if self._pending.t.size:
            self.blocks_skipped += 1
        m = self._s.shape[1]
        self._pending = _Pending(np.empty(0), np.empty((0, m)), np.empty((0, m)), np.empty(0), np.empty((0, m)))
        self._next_block = max(self._next_block, int(math.ceil((end - self.origin) / self.block - 1e-9)))
        self._next_eval = max(self._next_eval, int(math.ceil((end - self.origin) / self.every - 1e-9)))
        self._s[:] = 0.0
        self._zero_time[:] = end

    def _segment(self, t: np.ndarray, X: np.ndarray) -> np.ndarray:
        f, g, shift, var, c = self.forecast(t)
        r = X - f
        sd = np.sqrt(self.sigma2[None, :] + g * g * (var + PHASE_Z ** 2 * self.phase_error2)[:, None])
        z = r / sd
        ok = np.isfinite(z)
        z = np.where(ok, z, 0.0)
        p = self._pending
        p.t = np.concatenate([p.t, t])
        p.residual = np.vstack([p.residual, np.where(ok, r, np.nan)])
        p.slope = np.vstack([p.slope, g])
        p.shift = np.concatenate([p.shift, shift])
        p.correction = np.vstack([p.correction, c])
        self._cusum(t, z)
        return f

    def _cusum(self, t: np.ndarray, z: np.ndarray) -> None:
        """Run the statistics over ``z`` (samples × signals), vectorised while they stay below
        the limit; right after a crossing, sample by sample (:meth:`_cusum_scalar`): a fault
        keeps the restarted statistics crossing at almost every sample, and restarting the
        vectorised pass over the rest of the data at each crossing cost time quadratic in it."""
        k, h = self.design.k, self.design.h
        i = 0
        n = t.size
        while i < n:
            w = np.stack([z[i:] - k, -z[i:] - k])                    # (2, n-i, m)
            paths = np.empty_like(w)
            for side in range(2):
                for s in range(w.shape[2]):
                    paths[side, :, s] = cusum_path(w[side, :, s], self._s[side, s])
            over = paths > h
            crossed = over.any(axis=(0, 2))
            stop = int(np.argmax(crossed)) if crossed.any() else n - i
            seg_paths = paths[:, :stop + 1 if crossed.any() else stop, :]
            self._track_zero(t[i:i + seg_paths.shape[1]], seg_paths)
            self._record(t[i:i + seg_paths.shape[1]], seg_paths.max(axis=(0, 2)))
            if not crossed.any():
                self._s = paths[:, -1, :].copy()
                return
            at = i + stop
            side, sig = np.unravel_index(int(np.argmax(paths[:, stop, :])), (2, w.shape[2]))
            self._cross(float(t[at]), int(side), int(sig), float(paths[side, stop, sig]))
            i = self._cusum_scalar(t, z, at + 1)

    def _cross(self, time: float, side: int, sig: int, statistic: float) -> None:
        """A crossing at ``time``: tell the detector; every statistic restarts from zero."""
        self.detector.crossing(Crossing(time, self.names[sig], "+" if side == 0 else "-", statistic,
                                        self.design.h, float(self._zero_time[side, sig])))
        self._s[:] = 0.0
        self._zero_time[:] = time

    def _cusum_scalar(self, t: np.ndarray, z: np.ndarray, i: int) -> int:
        """The statistics sample by sample from index ``i`` until ``SCALAR_RUN`` samples pass
        without a crossing (or the data end); returns the next index.  The same recursion,
        zero times, evaluations and crossings as the vectorised pass, in scalar arithmetic."""
        k, h, eps = self.design.k, self.design.h, self._eps
        m = z.shape[1]
        s = [[float(v) for v in row] for row in self._s]
        zt = [[float(v) for v in row] for row in self._zero_time]
        due = self.origin + self._next_eval * self.every
        quiet = 0
        n = t.size
        base, tl, zl = i, [], []            # plain floats of a stretch of samples: indexing numpy costs more
        while i < n and quiet < SCALAR_RUN:
            if i - base >= len(tl):
                base = i
                tl, zl = t[i:i + 1024].tolist(), z[i:i + 1024].tolist()
            tj, zj = tl[i - base], zl[i - base]
            while tj > due + eps:                     # evaluations that passed before this sample
                self._evaluated(due)
                due = self.origin + self._next_eval * self.every
            best, best_side, best_sig = -math.inf, 0, 0
            up, down, up_zt, down_zt = s[0], s[1], zt[0], zt[1]
            for sig in range(m):
                x = zj[sig]
                v = up[sig] + x - k                   # the + side: w = z − k
                if v <= 0.0:
                    v = 0.0
                    up_zt[sig] = tj
                up[sig] = v
                if v > best:
                    best, best_side, best_sig = v, 0, sig
            for sig in range(m):
                v = down[sig] + -zj[sig] - k          # the − side: w = −z − k
                if v <= 0.0:
                    v = 0.0
                    down_zt[sig] = tj
                down[sig] = v
                if v > best:
                    best, best_side, best_sig = v, 1, sig
            if best > self._eval_max:
                self._eval_max = best
            if tj >= due - eps:                       # a sample at the evaluation time closes it
                self._evaluated(due)
                due = self.origin + self._next_eval * self.every
            if best > h:
                if not self.detector.extend(tj):      # a new alarm (not one latched already): the full crossing
                    self.detector.crossing(Crossing(tj, self.names[best_sig], "+" if best_side == 0 else "-", best,
                                                    h, zt[best_side][best_sig]))
                s = [[0.0] * m, [0.0] * m]
                zt = [[tj] * m, [tj] * m]
                quiet = 0
            else:
                quiet += 1
            i += 1
        self._s, self._zero_time = np.array(s), np.array(zt)
        return i

    def _track_zero(self, t: np.ndarray, paths: np.ndarray) -> None:
        """Remember, per statistic, the last time it was zero: the CUSUM's change-time estimate."""
        zero = paths <= 0.0
        any_zero = zero.any(axis=1)
        last = paths.shape[1] - 1 - np.argmax(zero[:, ::-1, :], axis=1)
        self._zero_time = np.where(any_zero, t[last], self._zero_time)

    def _record(self, t: np.ndarray, stat: np.ndarray) -> None:
        i = 0
        while i < t.size:
            due = self.origin + self._next_eval * self.every
            j = int(np.searchsorted(t, due + self._eps, side="right"))
            if j > i:
                self._eval_max = max(self._eval_max, float(stat[i:j].max()))
            if j < t.size or (t.size and t[-1] >= due - self._eps):
                self._evaluated(due)
            i = j

    def _evaluated(self, due: float) -> None:
        """Evaluation time ``due`` has passed: report the largest statistic since the last one."""
        h = self.design.h
        self.max_ratio = max(self.max_ratio, self._eval_max / h)
        self.detector.tick(due)
        self.on_evaluation(due, self._eval_max, h, self.detector.state)
        self._eval_max = 0.0
        self._next_eval += 1

    def _learn_phase_error(self, t: np.ndarray, shift_used: np.ndarray) -> None:
        """Compare the shift the CUSUM used with the tracker's estimate now that the block is in.

        The difference is the phase error the detector was exposed to at its prediction
        horizon (guard to guard + block).  Its mean square is kept as a peak that decays with
        ``PHASE_ERROR_MEMORY``: a machine whose phase wanders (a rotating crank's speed drifts
        with its energy) keeps its residual scale widened where the waveform is steep.
        """
        shift_now, _ = self.tracker.shift(t)
        err2 = float(np.mean((shift_used - shift_now) ** 2))
        end = float(t[-1])
        if self._phase_error_time is not None:
            self.phase_error2 *= math.exp(-max(end - self._phase_error_time, 0.0) / PHASE_ERROR_MEMORY)
        self._phase_error_time = end
        self.phase_error2 = max(self.phase_error2, err2)

    def _update_tracker(self) -> None:
        """Fold block ``(b − block, b]`` into the tracker if it is confirmed healthy; drop it."""
        end = self.origin + self._next_block * self.block
        start = end - self.block
        self._next_block += 1
        p = self._pending
        sel = (p.t > start + self._eps) & (p.t <= end + self._eps)
        healthy = self.detector.quiet_since(start)
        if healthy and sel.any():
            r = p.residual[sel]
            g = p.slope[sel]
            ok = np.isfinite(r).all(axis=1)
            if ok.any():
                m = r.shape[1]
                tt = np.repeat(p.t[sel][ok], m)
                self.tracker.update(tt, g[ok].ravel(), r[ok].ravel(), np.repeat(p.shift[sel][ok], m),
                                    np.tile(self.sigma2, int(ok.sum())))
                self._learn_phase_error(p.t[sel][ok], p.shift[sel][ok])
                if self.corrections is not None:
                    phase_t = p.t[sel][ok] - p.shift[sel][ok]
                    base = r[ok] + p.correction[sel][ok]          # residual from the template alone
                    for j, corr in enumerate(self.corrections):
                        corr.update(phase_t, base[:, j])
                    self.sigma2 = self._sigma2_noise * (1.0 + np.array([c.noise_ratio for c in self.corrections]))
                self.blocks_used += 1
        elif sel.any():
            self.blocks_skipped += 1
        keep = p.t > end + self._eps
        p.t, p.residual, p.slope, p.shift, p.correction = (p.t[keep], p.residual[keep], p.slope[keep], p.shift[keep],
                                                           p.correction[keep])
