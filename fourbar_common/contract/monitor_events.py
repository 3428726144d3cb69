"""``monitor/events.jsonl``: the monitor's events, one JSON object per line, typed.

Each line is one :class:`MonitorEvent`::

    {"time": 10.07, "event": "alarm", "state": "ALARM", "statistic": 41.2, "threshold": 30.9,
     "message": "Undefined signal ...", <the payload's fields>, "wall": "2026-...Z"}

``event`` is one of :data:`EVENT_KINDS`; ``state`` one of :data:`STATES` (read case-insensitively);
``message`` a string (absent: empty); ``statistic`` and
``threshold`` are numbers or null; ``wall`` the UTC time the line was written (ISO 8601).
What else a line holds is its *payload*, typed per event kind and detector:

=========  ===============================  ==================================================
kind       detector / ``reason``            payload
=========  ===============================  ==================================================
trained    cusum                            :class:`CusumTrained`
trained    mae                              :class:`MaeTrained`
trained    page-hinkley                     :class:`PageHinkleyTrained`
alarm      reason cusum, page-hinkley       :class:`ChangeAlarm` (signal, side, onset, episode)
alarm      reason mae, refit_limit          :class:`RuleAlarm`
refit      mae (``refit="paper"``)          :class:`RefitWindow`
stable,    any                              :class:`NoPayload`
clear
any        another (registered) detector    :class:`OtherPayload` (its fields as written)
=========  ===============================  ==================================================

The payload's fields follow the fixed ones on the line, in the order above's classes declare
them, so :meth:`MonitorEvent.to_json` writes the bytes the monitor always wrote.  A reader
calls :meth:`MonitorEvent.from_json` (or :meth:`MonitorEvent.from_dict` with a line already
parsed); a line that is not an event raises :class:`~fourbar_common.contract.problems.ContractError`
listing every problem (field, message).  :data:`SCHEMA_VERSION` is the version of this layout.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, fields
from typing import Any, ClassVar, Mapping

from .json_files import JsonFileError, parse_json
from .problems import ContractError, Problem

__all__ = ["ChangeAlarm", "CusumTrained", "EVENT_KINDS", "MaeTrained", "ModelFitted", "MonitorEvent", "NoPayload", "read_growing_events",
           "OtherPayload", "PageHinkleyTrained", "Payload", "RefitWindow", "RuleAlarm", "SCHEMA_VERSION", "STATES",
           "TYPED_DETECTORS", "read_events"]

SCHEMA_VERSION = 1
EVENT_KINDS = ("trained", "stable", "refit", "alarm", "clear")
STATES = ("TRAINING", "STABLE", "ALARM")
_FIXED = ("time", "event", "state", "statistic", "threshold", "message")


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _check(value: Any, kind: str) -> Any:
    """``value`` as the field type ``kind`` (raises ValueError naming what was expected)."""
    if kind == "float":
        if _is_number(value):
            return float(value)
        raise ValueError(f"expected a number, got {value!r}")
    if kind == "float?":
        return None if value is None else _check(value, "float")
    if kind == "int":
        if isinstance(value, int) and not isinstance(value, bool):
            return value
        raise ValueError(f"expected an integer, got {value!r}")
    if kind == "str":
        if isinstance(value, str):
            return value
        raise ValueError(f"expected a string, got {value!r}")
    if kind == "names":
        if isinstance(value, list) and all(isinstance(v, str) for v in value):
            return tuple(value)
        raise ValueError(f"expected a list of column names, got {value!r}")
    if kind == "per_signal":
        if isinstance(value, dict) and all(isinstance(k, str) and (v is None or _is_number(v)) for k, v in value.items()):
            return tuple((k, None if v is None else float(v)) for k, v in value.items())
        raise ValueError(f"expected an object of numbers by column name, got {value!r}")
    raise AssertionError(kind)


def typed(kind: str, *, optional: bool = False) -> Any:
    """A payload field of type ``kind`` (float, float?, int, str, names, per_signal); ``optional``:
    absent from the line when None."""
    meta = {"kind": kind, "optional": optional}
    return field(default=None, metadata=meta) if optional else field(metadata=meta)


@dataclass(frozen=True)
class Payload:
    """What a line holds beyond the fixed fields (module docstring)."""

    def as_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if v is None and f.metadata.get("optional"):
                continue
            kind = f.metadata.get("kind")
            out[f.name] = list(v) if kind == "names" else dict(v) if kind == "per_signal" else v
        return out

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], problems: list[Problem]) -> "Payload | None":
        values, ok = {}, True
        for f in fields(cls):
            if f.name not in d:
                if f.metadata.get("optional"):
                    continue
                problems.append(Problem(f.name, f"missing (a {cls.__name__} payload)"))
                ok = False
                continue
            try:
                values[f.name] = _check(d[f.name], f.metadata["kind"])
            except ValueError as exc:
                problems.append(Problem(f.name, str(exc)))
                ok = False
        return cls(**values) if ok else None


@dataclass(frozen=True)
class NoPayload(Payload):
    """A ``stable`` or ``clear`` event: nothing beyond the fixed fields."""


@dataclass(frozen=True)
class ModelFitted(Payload):
    """What every built-in ``trained`` event carries: the fitted period and model."""

    period_fft_s: float = typed("float")
    period_s: float = typed("float")
    period_stderr_s: float | None = typed("float?")
    model: str = typed("str")
    order: int = typed("int")
    fit_seconds: float = typed("float")
    train_start: float = typed("float")
    train_end: float = typed("float")
    detector: str = typed("str")


@dataclass(frozen=True)
class CusumTrained(ModelFitted):
    """The cusum detector's ``trained`` event: its design and each column's noise scale and period."""

    signals: tuple[str, ...] = typed("names")
    cusum_k: float = typed("float")
    cusum_h: float = typed("float")
    arl0_hours: float = typed("float")
    noise_sigma: tuple[tuple[str, float], ...] = typed("per_signal")
    signal_periods_s: tuple[tuple[str, float], ...] = typed("per_signal")


@dataclass(frozen=True)
class MaeTrained(ModelFitted):
    """The mae detector's ``trained`` event: its threshold rule."""

    threshold_base: float = typed("float")
    threshold_slope_per_s: float = typed("float")
    validation_mae_max: float | None = typed("float", optional=True)


@dataclass(frozen=True)
class PageHinkleyTrained(ModelFitted):
    """The page-hinkley detector's ``trained`` event: its design and noise scale."""

    signals: tuple[str, ...] = typed("names")
    ph_delta: float = typed("float")
    ph_h: float = typed("float")
    arl0_hours: float = typed("float")
    noise_sigma: tuple[tuple[str, float], ...] = typed("per_signal")


@dataclass(frozen=True)
class ChangeAlarm(Payload):
    """An ``alarm`` of a sequential test (``reason`` cusum or page-hinkley): on which column and
    side, when the change began (the statistic's last zero), which alarm episode."""

    reason: str = typed("str")
    signal: str = typed("str")
    side: str = typed("str")
    onset: float = typed("float")
    episode: int = typed("int")


@dataclass(frozen=True)
class RuleAlarm(Payload):
    """An ``alarm`` of the MAE rule: ``reason`` mae (the threshold) or refit_limit."""

    reason: str = typed("str")


@dataclass(frozen=True)
class RefitWindow(Payload):
    """A ``refit`` event: the window the new model is fitted on (s)."""

    train_start: float = typed("float")
    train_end: float = typed("float")


@dataclass(frozen=True)
class OtherPayload(Payload):
    """The payload of a detector this contract does not type (one registered by a user): its
    fields as written, JSON values."""

    values: tuple[tuple[str, Any], ...] = ()

    def as_dict(self) -> dict[str, Any]:
        return dict(self.values)


_TRAINED = {"cusum": CusumTrained, "mae": MaeTrained, "page-hinkley": PageHinkleyTrained}
#: The detectors whose payloads this contract types (the built-in ones).
TYPED_DETECTORS = tuple(_TRAINED)
_ALARMS = {"cusum": ChangeAlarm, "page-hinkley": ChangeAlarm, "mae": RuleAlarm, "refit_limit": RuleAlarm}


def payload_class(kind: str, data: Mapping[str, Any]) -> type[Payload]:
    """The payload type of an event of ``kind`` whose payload fields are ``data``."""
    if kind == "trained":
        return _TRAINED.get(data.get("detector"), OtherPayload) if data else OtherPayload  # type: ignore[arg-type]
    if kind == "alarm":
        return _ALARMS.get(data.get("reason"), OtherPayload)  # type: ignore[arg-type]
    if kind == "refit" and set(data) == {"train_start", "train_end"}:
        return RefitWindow
    return NoPayload if not data else OtherPayload


@dataclass(frozen=True)
class MonitorEvent:
    """One line of events.jsonl: a state change or alarm of the monitor at data ``time`` (s)."""

    time: float
    event: str                     # trained | stable | refit | alarm | clear
    state: str                     # the state after it: TRAINING | STABLE | ALARM
    statistic: float | None
    threshold: float | None
    message: str
    payload: Payload = NoPayload()
    wall: str | None = None        # when it was written (UTC, ISO 8601)

    schema_version: ClassVar[int] = SCHEMA_VERSION

    @property
    def train_start(self) -> float | None:
        """The start of the window a ``trained`` or ``refit`` event's model is fitted on."""
        return getattr(self.payload, "train_start", None)

    @property
    def train_end(self) -> float | None:
        return getattr(self.payload, "train_end", None)

    def as_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"time": self.time, "event": self.event, "state": self.state,
                             "statistic": self.statistic, "threshold": self.threshold, "message": self.message}
        d.update(self.payload.as_dict())
        if self.wall is not None:
            d["wall"] = self.wall
        return d

    def to_json(self) -> str:
        """The line (without its newline); non-finite numbers are written as null."""
        return json.dumps(_finite(self.as_dict()), allow_nan=False)

    @classmethod
    def from_dict(cls, data: Any, source: str = "events.jsonl", *, strict: bool = False) -> "MonitorEvent":
        """The event of one parsed line; :class:`ContractError` lists every problem.

        The payload is typed when its fields are those of its kind's payload class (a value of
        the wrong type is a problem); otherwise it is an :class:`OtherPayload` (a detector
        registered by a user may give its alarms any fields), unless ``strict``: then a missing
        or extra field is a problem too (what the monitor writes for a built-in detector).
        """
        if not isinstance(data, dict):
            raise ContractError(source, [Problem("", f"expected a JSON object, got {type(data).__name__}")])
        problems: list[Problem] = []
        if not _is_number(data.get("time")):
            problems.append(Problem("time", f"expected a number of seconds, got {data.get('time')!r}"))
        kind = data.get("event")
        if kind not in EVENT_KINDS:
            problems.append(Problem("event", f"expected one of {', '.join(EVENT_KINDS)}, got {kind!r}"))
        state = data.get("state")
        state = state.upper() if isinstance(state, str) else state        # read case-insensitively
        if state not in STATES:
            problems.append(Problem("state", f"expected one of {', '.join(STATES)}, got {data.get('state')!r}"))
        for name in ("statistic", "threshold"):
            if data.get(name) is not None and not _is_number(data.get(name)):
                problems.append(Problem(name, f"expected a number or null, got {data.get(name)!r}"))
        if not isinstance(data.get("message", ""), str):
            problems.append(Problem("message", f"expected a string, got {data.get('message')!r}"))
        wall = data.get("wall")
        if wall is not None and not isinstance(wall, str):
            problems.append(Problem("wall", f"expected an ISO 8601 time, got {wall!r}"))
        rest = {k: v for k, v in data.items() if k not in _FIXED and k != "wall"}
        payload: Payload | None = NoPayload()
        if kind in EVENT_KINDS:
            cls_ = payload_class(kind, rest)
            names = {f.name for f in fields(cls_)}
            required = {f.name for f in fields(cls_) if not f.metadata.get("optional")}
            fits = required <= set(rest) <= names
            if cls_ is OtherPayload or (not strict and not fits):
                payload = OtherPayload(tuple(rest.items()))
            else:
                extra = sorted(set(rest) - {f.name for f in fields(cls_)})
                problems += [Problem(k, f"not a field of a {kind} event ({cls_.__name__})") for k in extra]
                payload = cls_.from_dict(rest, problems)
        if problems:
            raise ContractError(source, problems)
        return cls(float(data["time"]), kind, state,
                   None if data.get("statistic") is None else float(data["statistic"]),
                   None if data.get("threshold") is None else float(data["threshold"]),
                   data.get("message") or "", payload, wall)  # type: ignore[arg-type]

    @classmethod
    def from_json(cls, line: str, source: str = "events.jsonl") -> "MonitorEvent":
        """The event of one line of text; :class:`ContractError` when it is not JSON or not an event."""
        try:
            data = json.loads(line)
        except (ValueError, RecursionError) as exc:
            raise ContractError(source, [Problem("", f"not JSON: {exc}")]) from None
        return cls.from_dict(data, source)

    @classmethod
    def build(cls, time: float, event: str, state: str, statistic: float | None, threshold: float | None,
              message: str, data: Mapping[str, Any], wall: str | None = None, *,
              detector: str = "") -> "MonitorEvent":
        """The typed event of a detector's event (``data``: its payload fields, JSON values);
        strict (:meth:`from_dict`) for the built-in ``detector`` names this contract types."""
        return cls.from_dict(_finite({"time": time, "event": event, "state": state, "statistic": statistic,
                                      "threshold": threshold, "message": message, **data,
                                      **({"wall": wall} if wall is not None else {})}), "event",
                             strict=detector in TYPED_DETECTORS)


def read_events(text: str, source: str = "events.jsonl") -> list[MonitorEvent]:
    """Every event of an events.jsonl text (blank lines skipped); the first bad line raises
    :class:`ContractError` naming it (``source:N``)."""
    out = []
    for n, line in enumerate(text.splitlines(), 1):
        if line.strip():
            out.append(MonitorEvent.from_json(line, f"{source}:{n}"))
    return out


def read_growing_events(text: str, source: str = "events.jsonl") -> tuple[list[MonitorEvent], list[str]]:
    """The events of the complete lines of an events.jsonl that is still being written, for a live
    reader that must go on: a line that is not JSON is skipped with a warning naming it (returned
    second), and a JSON line that is not one of the monitor's events is skipped silently."""
    events, warnings = [], []
    for line in text.split("\n"):
        if not line.strip():
            continue
        try:
            data = parse_json(line, source)
        except JsonFileError as exc:       # not JSON, or nested too deeply
            warnings.append(f"{exc}; the line was skipped")
            continue
        try:
            events.append(MonitorEvent.from_dict(data, source))
        except ContractError:              # not an event of the monitor's
            continue
    return events, warnings


def _finite(value: Any) -> Any:
    """Non-finite floats → None (JSON has no NaN), recursively."""
    if isinstance(value, dict):
        return {str(k): _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value
