"""Forecast models of a periodic signal: Prophet (the paper's) and a harmonic baseline.

Both are fitted on the training window with the period found by
:func:`monitor.spectrum.dominant_period` and expose ``predict(t) -> ndarray`` for any array
of times (seconds, the exchange file's time axis).

``prophet``
    ``Prophet(growth="flat", yearly/weekly/daily_seasonality=False,
    uncertainty_samples=0)`` plus one custom seasonality ``"cycle"`` of period
    ``P / 86400`` days and Fourier order ``order`` (default 30: this signal has sharp flat
    bottoms and a double hump, so it needs many harmonics; a 3.06 s period at 0.01 s
    steps allows up to 151).  Sample times become ``ds = epoch + t seconds`` with the
    fixed epoch 1970-01-01 (Prophet's own time origin, so ``t`` keeps full precision in
    days).  The Stan optimiser gets a fixed ``seed`` and at most 1000 iterations.  Prophet and cmdstanpy log at INFO
    level; that is silenced for the duration of the fit and predict calls only.

    A Prophet ``predict`` costs 30-80 ms whatever its length, so predictions are made
    ahead in chunks of ``chunk_seconds`` (20 s) on the sample grid of the training data
    (``t0 + k·dt``) and cached (a few chunks, bounded memory); a time off that grid is
    predicted directly.  Both models use this cache (see :class:`Forecaster`).

``harmonic``
    Least-squares Fourier series of the same order on the same period
    (:func:`monitor.spectrum.fit_fourier`): the model Prophet's seasonality term reduces
    to when its trend is flat, without the Stan optimiser.  Microseconds per prediction.
"""
from __future__ import annotations

import logging
import time
import warnings
from collections import OrderedDict
from contextlib import contextmanager
from typing import Any, Iterator

import numpy as np

from .errors import OptionError, TrainingError
from .spectrum import fit_fourier, fourier_design, max_fourier_order

__all__ = ["Forecaster", "HarmonicForecaster", "ProphetForecaster", "fit_forecaster", "forecaster_class",
           "forecaster_names", "quiet_prophet", "MODELS", "PROPHET_EPOCH", "register_forecaster"]

#: Datetime of t = 0 s in the frame given to Prophet.
PROPHET_EPOCH = "1970-01-01 00:00:00"
_LOGGERS = ("prophet", "prophet.plot", "prophet.models", "prophet.forecaster", "cmdstanpy")


@contextmanager
def quiet_prophet() -> Iterator[None]:
    """Silence Prophet/cmdstanpy logging and warnings inside the block; restore them after."""
    saved = []
    for name in _LOGGERS:
        logger = logging.getLogger(name)
        saved.append((logger, logger.level, logger.disabled))
        logger.setLevel(logging.CRITICAL + 1)
        logger.disabled = True
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            yield
    finally:
        for logger, level, disabled in saved:
            logger.setLevel(level)
            logger.disabled = disabled


class Forecaster:
    """A fitted model: ``predict(t)`` returns the forecast at the times ``t`` (seconds).

    Predictions at times on the sampling grid of the training data (``t0 + k·dt``) are
    computed in fixed chunks of that grid (``chunk_seconds``) and cached (``max_chunks``):
    fast for Prophet, and the value at a given time never depends on which other times
    were asked for together, so a file read in blocks (following) and read at once
    (replay) get bit-identical forecasts.  Times off the grid are predicted directly.
    """

    kind: str = ""

    def _setup(self, t: np.ndarray, x: np.ndarray, period: float, order: int, fit_seconds: float,
               chunk_seconds: float, max_chunks: int = 4) -> None:
        self.period = float(period)
        self.order = int(order)
        self.fit_seconds = float(fit_seconds)
        self.train_start = float(t[0])
        self.train_end = float(t[-1])
        self.n_train = int(t.size)
        self._dt = float(np.median(np.diff(t)))
        self._t0 = float(t[0])
        self._chunk = max(1, int(round(chunk_seconds / self._dt)))
        self.chunk_seconds = self._chunk * self._dt
        self._max_chunks = max(1, int(max_chunks))
        self._cache: OrderedDict[int, np.ndarray] = OrderedDict()
        self.predict_calls = 0
        self.train_mae = float(np.mean(np.abs(self.predict(t) - x)))

    @classmethod
    def warm_up(cls) -> None:
        """Import the libraries a fit will need (a live monitor then reacts at once); none by default."""

    def predict_direct(self, t: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def predict(self, t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=float).ravel()
        result = np.empty(t.size)
        k = np.rint((t - self._t0) / self._dt)
        on_grid = (np.abs(t - (self._t0 + k * self._dt)) <= 1e-6 * self._dt) & (k >= 0)
        k = k.astype(np.int64)
        if on_grid.any():
            where = np.flatnonzero(on_grid)
            chunk_ids = k[where] // self._chunk
            for c in np.unique(chunk_ids):
                values = self._chunk_values(int(c))
                sel = where[chunk_ids == c]
                result[sel] = values[k[sel] - c * self._chunk]
        if not on_grid.all():
            result[~on_grid] = self._direct(t[~on_grid])
        return result

    def _direct(self, t: np.ndarray) -> np.ndarray:
        self.predict_calls += 1
        return self.predict_direct(t)

    def _chunk_values(self, c: int) -> np.ndarray:
        values = self._cache.get(c)
        if values is None:
            grid = self._t0 + self._dt * np.arange(c * self._chunk, (c + 1) * self._chunk)
            values = self._direct(grid)
            self._cache[c] = values
            while len(self._cache) > self._max_chunks:
                self._cache.popitem(last=False)
        else:
            self._cache.move_to_end(c)
        return values

    def settings(self) -> dict[str, Any]:
        return {"kind": self.kind, "period_s": self.period, "order": self.order,
                "fit_seconds": self.fit_seconds, "train_start": self.train_start,
                "train_end": self.train_end, "n_train": self.n_train, "train_mae": self.train_mae,
                "chunk_seconds": round(self.chunk_seconds, 9), "predict_calls": self.predict_calls}


class HarmonicForecaster(Forecaster):
    """Least-squares Fourier series ``a0 + Σ a_k cos(2πkt/P) + b_k sin(2πkt/P)``."""

    kind = "harmonic"

    def __init__(self, t: np.ndarray, x: np.ndarray, period: float, order: int, *, seed: int = 0,
                 chunk_seconds: float = 20.0):
        del seed                # a least-squares fit draws no random numbers
        start = time.perf_counter()
        self.coef, _ = fit_fourier(t, x, period, order)
        self._setup(t, x, period, order, time.perf_counter() - start, chunk_seconds)

    def predict_direct(self, t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=float).ravel()
        return fourier_design(t, self.period, self.order) @ self.coef


class ProphetForecaster(Forecaster):
    """Prophet with flat growth and one custom seasonality at the given period."""

    kind = "prophet"

    #: Iteration limit of Stan's L-BFGS (Prophet's default is 10 000).  A noise-free signal that
    #: the Fourier series represents exactly drives ``sigma_obs`` to 0 and the optimiser would
    #: creep on for a minute; the coefficients are exact long before.  Real data converge in
    #: ~100-300 iterations.
    max_iter = 1000

    def __init__(self, t: np.ndarray, x: np.ndarray, period: float, order: int, *, seed: int = 0,
                 chunk_seconds: float = 20.0):
        import pandas as pd

        with quiet_prophet():
            from prophet import Prophet

            self.seed = int(seed)
            self._epoch = pd.Timestamp(PROPHET_EPOCH)
            start = time.perf_counter()
            model = Prophet(growth="flat", yearly_seasonality=False, weekly_seasonality=False,
                            daily_seasonality=False, uncertainty_samples=0)
            model.add_seasonality(name="cycle", period=period / 86400.0, fourier_order=int(order))
            model.fit(pd.DataFrame({"ds": self._ds(t), "y": np.asarray(x, dtype=float)}), seed=self.seed,
                      iter=self.max_iter)
            fit_seconds = time.perf_counter() - start
        self.model = model
        self._setup(t, x, period, order, fit_seconds, chunk_seconds)

    @classmethod
    def warm_up(cls) -> None:
        with quiet_prophet():
            import prophet  # noqa: F401

    def _ds(self, t: np.ndarray) -> "Any":
        import pandas as pd

        ns = np.rint(np.asarray(t, dtype=float) * 1e9).astype("int64")
        return self._epoch + pd.to_timedelta(ns, unit="ns")

    def predict_direct(self, t: np.ndarray) -> np.ndarray:
        """One Prophet ``predict`` call for exactly these times (no cache)."""
        import pandas as pd

        t = np.asarray(t, dtype=float).ravel()
        if t.size == 0:
            return np.empty(0)
        with quiet_prophet():
            out = self.model.predict(pd.DataFrame({"ds": self._ds(t)}))
        return out["yhat"].to_numpy(dtype=float)

    def settings(self) -> dict[str, Any]:
        d = super().settings()
        d.update({"growth": "flat", "seasonality": {"name": "cycle", "period_days": self.period / 86400.0,
                                                    "fourier_order": self.order},
                  "builtin_seasonalities": False, "uncertainty_samples": 0, "seed": self.seed,
                  "epoch": PROPHET_EPOCH, "max_iter": self.max_iter})
        return d


#: The registry: the ``model`` option's values and the classes they name, built-ins first.
_REGISTRY: dict[str, type[Forecaster]] = {}


def register_forecaster(cls: type[Forecaster]) -> type[Forecaster]:
    """Make ``cls`` available as ``model=cls.kind``; returns ``cls`` (usable as a decorator).

    ``cls(t, x, period, order, *, seed, chunk_seconds)`` fits on the training samples; a
    heavy library (Prophet) is imported in that constructor, never at module import.
    """
    if not (isinstance(cls, type) and issubclass(cls, Forecaster)) or not cls.kind:
        raise TypeError(f"register_forecaster: expected a subclass of Forecaster with a kind, got {cls!r}")
    known = _REGISTRY.get(cls.kind)
    if known is not None and known is not cls:
        raise ValueError(f"register_forecaster: model name {cls.kind!r} is taken by {known.__name__}")
    _REGISTRY[cls.kind] = cls
    return cls


def forecaster_names() -> tuple[str, ...]:
    """The accepted values of the ``model`` option, the default (``prophet``) first."""
    return tuple(_REGISTRY)


def forecaster_class(kind: str) -> type[Forecaster]:
    """The class registered as ``kind`` (raises :class:`OptionError` for an unknown name)."""
    try:
        return _REGISTRY[kind]
    except (KeyError, TypeError):
        raise OptionError(f"model: {kind!r} is not a model; expected one of {', '.join(_REGISTRY)}") from None


def fit_forecaster(kind: str, t: np.ndarray, x: np.ndarray, period: float, *, order: int = 30,
                   seed: int = 0, chunk_seconds: float = 20.0) -> Forecaster:
    """Fit a forecaster of ``kind`` (a registered model: ``"prophet"``, ``"harmonic"``) on samples ``(t, x)``.

    ``period`` is the fundamental period in seconds (the refined one); ``order`` the Fourier
    order, capped at :func:`~monitor.spectrum.max_fourier_order` for the sampling.
    ``seed`` (Prophet's optimiser) is ignored by the harmonic model; ``chunk_seconds`` is
    the length of the cached prediction chunks (see :class:`Forecaster`).
    """
    cls = forecaster_class(kind)
    t = np.asarray(t, dtype=float)
    x = np.asarray(x, dtype=float)
    if t.ndim != 1 or t.shape != x.shape or t.size < 16:
        raise TrainingError(f"need at least 16 training samples in 1-D arrays of equal length, got "
                            f"{t.shape} and {x.shape}")
    if not (np.isfinite(period) and period > 0):
        raise TrainingError(f"period must be a positive number of seconds, got {period!r}")
    if int(order) < 1:
        raise OptionError(f"order: Fourier order must be at least 1, got {order!r}")
    dt = float(np.median(np.diff(t)))
    order = min(int(order), max_fourier_order(period, dt, t.size))
    return cls(t, x, period, order, seed=seed, chunk_seconds=chunk_seconds)


for _cls in (ProphetForecaster, HarmonicForecaster):      # the default first
    register_forecaster(_cls)
#: The built-in model kinds (the registry may hold more: :func:`forecaster_names`).
MODELS = forecaster_names()
