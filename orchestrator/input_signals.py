"""Input signals of a case file (``[inputs]``): what each FMU input is given over time.

Each signal is a frozen dataclass with one call, ``at(t, order)``: its value (``order = 0``)
or its exact ``order``-th time derivative (1 or 2) at time ``t`` in s.  Piecewise signals are
*right-continuous*: at a breakpoint (a step's time, a ramp's corners, a table's rows) the value
and the derivatives are those of the piece that starts there, which is what the FMU sees over
the communication step that starts at that time.  A jump has no derivative: the derivatives of
a step are 0 on both sides.

- :class:`Constant`  ``u = value``
- :class:`Step`      ``u = before`` for ``t < time``, ``after`` for ``t >= time``
- :class:`Ramp`      ``u = from`` for ``t < start``, ``from + slope*(t - start)`` until ``end``, then ``to``
  (``end = start + duration``; without ``to`` the ramp never ends)
- :class:`Sine`      ``u = offset + amplitude*sin(2*pi*frequency*t + phase)`` (frequency in Hz, phase in rad)
- :class:`Table`     rows ``(t_i, u_i)``, linear between rows, the first value held before the
  first row and the last after the last (as ``numpy.interp`` and FMPy's input arrays); a time
  given twice is a step: the second row's value holds from that time on
- :class:`CsvColumn` a :class:`Table` read from a CSV file's time column and one value column

:func:`parse_inputs` checks a case file's ``[inputs]`` table (every problem reported through a
:class:`~orchestrator.validation.ProblemReporter`); a CSV file is data, never code: read with
the ``csv`` module, every cell a finite decimal number, problems named by file, row and column.
:func:`derivative_order` is the highest input derivative an FMU's model description accepts.

Standard library only.
"""
from __future__ import annotations

import bisect
import csv
import hashlib
import io
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Mapping, Union

from fourbar_common.files import NotRegularFileError, open_regular

from .validation import ProblemReporter, kind_of, show_value

__all__ = ["INPUT_TYPES", "MAX_CSV_BYTES", "MAX_ORDER", "Constant", "CsvColumn", "Derivative", "InputSignal", "Ramp",
           "Sine", "Step", "Table", "derivative_order", "driver_rates", "parse_inputs", "recorded_signals"]

#: The largest CSV file an input is read from (bytes): 64 MB is a million rows of two columns.
MAX_CSV_BYTES = 64 << 20


#: The highest derivative order a signal gives: 2 for an input's own interpolation, 4 for the
#: second derivative of a driver's acceleration input (:class:`Derivative` of order 2).
MAX_ORDER = 4


def _check_order(order: int) -> None:
    if not isinstance(order, int) or not 0 <= order <= MAX_ORDER:
        raise ValueError(f"order: expected 0 (value) to {MAX_ORDER} (derivative), got {order!r}")


@dataclass(frozen=True)
class Constant:
    """``u(t) = value``."""

    KIND: ClassVar[str] = "constant"
    value: float

    def at(self, t: float, order: int = 0) -> float:
        _check_order(order)
        return self.value if order == 0 else 0.0

    def as_dict(self) -> dict:
        return {"type": self.KIND, "value": self.value}

    def as_toml(self) -> dict:
        """The signal as the case file gives it (what a re-validation reads)."""
        return self.as_dict()


@dataclass(frozen=True)
class Step:
    """``u(t) = before`` for ``t < time``, ``after`` from ``time`` on (derivatives 0)."""

    KIND: ClassVar[str] = "step"
    before: float
    after: float
    time: float

    def at(self, t: float, order: int = 0) -> float:
        _check_order(order)
        if order:
            return 0.0
        return self.after if t >= self.time else self.before

    def as_dict(self) -> dict:
        return {"type": self.KIND, "before": self.before, "after": self.after, "time": self.time}

    def as_toml(self) -> dict:
        """The signal as the case file gives it (what a re-validation reads)."""
        return self.as_dict()


@dataclass(frozen=True)
class Ramp:
    """``u = from_`` before ``start``, then ``from_ + slope*(t - start)``; after ``duration`` s
    the value reached then (``duration`` None: the ramp never ends)."""

    KIND: ClassVar[str] = "ramp"
    from_: float
    start: float
    slope: float
    duration: float | None = None

    @property
    def end(self) -> float | None:
        return None if self.duration is None else self.start + self.duration

    @property
    def to(self) -> float | None:
        return None if self.duration is None else self.from_ + self.slope * self.duration

    def at(self, t: float, order: int = 0) -> float:
        _check_order(order)
        end = self.end
        if order >= 2:
            return 0.0
        if order == 1:
            return self.slope if t >= self.start and (end is None or t < end) else 0.0
        if t < self.start:
            return self.from_
        if end is not None and t >= end:
            return self.to
        return self.from_ + self.slope * (t - self.start)

    def as_toml(self) -> dict:
        data = {"type": self.KIND, "from": self.from_, "start": self.start, "slope": self.slope}
        if self.duration is not None:
            data["duration"] = self.duration
        return data

    def as_dict(self) -> dict:
        data = self.as_toml()
        if self.duration is not None:
            data["to"] = self.to
        return data


@dataclass(frozen=True)
class Sine:
    """``u(t) = offset + amplitude*sin(2*pi*frequency*t + phase)``; frequency in Hz, phase in rad."""

    KIND: ClassVar[str] = "sine"
    amplitude: float
    frequency: float
    phase: float = 0.0
    offset: float = 0.0

    def at(self, t: float, order: int = 0) -> float:
        _check_order(order)
        w = 2.0 * math.pi * self.frequency
        arg = w * t + self.phase
        if order == 0:
            return self.offset + self.amplitude * math.sin(arg)
        # d^n/dt^n sin(arg) = w^n sin(arg + n*pi/2): cos, -sin, -cos, sin
        return self.amplitude * w ** order * (math.cos, _neg_sin, _neg_cos, math.sin)[(order - 1) % 4](arg)

    def as_dict(self) -> dict:
        return {"type": self.KIND, "amplitude": self.amplitude, "frequency": self.frequency, "phase": self.phase,
                "offset": self.offset}

    def as_toml(self) -> dict:
        """The signal as the case file gives it (what a re-validation reads)."""
        return self.as_dict()


def _neg_sin(x: float) -> float:
    return -math.sin(x)


def _neg_cos(x: float) -> float:
    return -math.cos(x)


@dataclass(frozen=True)
class Table:
    """Rows ``(times[i], values[i])``, times non-decreasing: linear between rows, held outside;
    a time given twice is a step (the later row holds from that time on)."""

    KIND: ClassVar[str] = "table"
    times: tuple[float, ...]
    values: tuple[float, ...]

    def _segment(self, t: float) -> int | None:
        """Index ``i`` of the piece ``[times[i], times[i+1])`` holding ``t``; None outside the rows."""
        i = bisect.bisect_right(self.times, t) - 1
        return i if 0 <= i < len(self.times) - 1 else None

    def at(self, t: float, order: int = 0) -> float:
        _check_order(order)
        i = self._segment(t)
        if i is None:
            return (self.values[0] if t < self.times[0] else self.values[-1]) if order == 0 else 0.0
        if order >= 2:
            return 0.0
        t0, t1, v0, v1 = self.times[i], self.times[i + 1], self.values[i], self.values[i + 1]
        if order == 1:
            return (v1 - v0) / (t1 - t0)    # t0 < t1: bisect_right skips a repeated time
        return v0 + (v1 - v0) * ((t - t0) / (t1 - t0))

    def as_dict(self) -> dict:
        return {"type": self.KIND, "rows": [[t, v] for t, v in zip(self.times, self.values)]}

    def as_toml(self) -> dict:
        """The signal as the case file gives it (what a re-validation reads)."""
        return self.as_dict()


@dataclass(frozen=True)
class CsvColumn(Table):
    """A :class:`Table` read from ``file``'s columns ``time`` and ``column`` (the file's SHA-256
    is recorded, so run.json says which data drove the run)."""

    KIND: ClassVar[str] = "csv"
    file: str = ""
    time_column: str = "time"
    column: str = ""
    sha256: str = ""

    def as_dict(self) -> dict:
        return {**self.as_toml(), "rows": len(self.times), "sha256": self.sha256}

    def as_toml(self) -> dict:
        return {"type": self.KIND, "file": self.file, "time": self.time_column, "column": self.column}


@dataclass(frozen=True)
class Derivative:
    """The ``order``-th time derivative of the signal of input ``of``: what a driver's rate and
    acceleration inputs (``<name>_d``, ``<name>_dd``, docs/mechanisms.md) are given when the
    case gives the position ``<name>`` alone, so that the FMU's Φt and Φtt stay exact."""

    KIND: ClassVar[str] = "derivative"
    signal: Constant | Step | Ramp | Sine | Table
    order: int
    of: str

    def at(self, t: float, order: int = 0) -> float:
        _check_order(order + self.order)
        return self.signal.at(t, order + self.order)

    def as_dict(self) -> dict:
        return {"type": self.KIND, "of": self.of, "order": self.order}


InputSignal = Union[Constant, Step, Ramp, Sine, Table, CsvColumn, Derivative]

#: The keys of each signal type in a case file: (required, optional).
INPUT_TYPES: Mapping[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    "constant": (("value",), ()),
    "step": (("before", "after", "time"), ()),
    "ramp": (("from", "start"), ("to", "duration", "slope")),
    "sine": (("amplitude", "frequency"), ("phase", "offset")),
    "table": (("rows",), ()),
    "csv": (("file", "column"), ("time",)),
}


def derivative_order(model_description) -> int:
    """The input derivative order set through ``fmi2SetRealInputDerivatives`` unless the case
    says otherwise: 0 unless it is an FMI 2.0 co-simulation FMU with ``canInterpolateInputs``;
    then 1, or 2 when its ``maxOutputDerivativeOrder`` is 2 or more.

    FMI 2.0 declares no highest input derivative order: ``canInterpolateInputs`` promises the
    first derivative (the input linear within the step); the FMU's own highest output
    derivative order is taken as a sign it interpolates to that order (quadratic from 2).  A
    case may ask for order 2 (``input_derivatives = 2``) of any FMU that can interpolate inputs.
    FMI 3.0 co-simulation has no input derivatives (0).
    """
    cs = getattr(model_description, "coSimulation", None)
    if cs is None or not str(model_description.fmiVersion).startswith("2") or not cs.canInterpolateInputs:
        return 0
    return 2 if (cs.maxOutputDerivativeOrder or 0) >= 2 else 1


# ---------------------------------------------------------------------------- the case file

#: The suffixes of a driver input's rate and acceleration inputs, by derivative order.
DRIVER_RATES = {1: "_d", 2: "_dd"}


def driver_rates(signals: Mapping[str, InputSignal], inputs: Mapping[str, Any]) -> dict[str, Derivative]:
    """The rate and acceleration inputs a case leaves to the orchestrator: for each input
    ``<name>`` it gives whose FMU also has the inputs ``<name>_d`` and ``<name>_dd`` (a driver
    input, docs/mechanisms.md), each of those the case does not give is the signal's exact
    first or second derivative (a driver's Φt and Φtt stay exact)."""
    derived: dict[str, Derivative] = {}
    for name, signal in signals.items():
        if isinstance(signal, Derivative) or not all(name + suffix in inputs for suffix in DRIVER_RATES.values()):
            continue
        for order, suffix in DRIVER_RATES.items():
            if name + suffix not in signals:
                derived[name + suffix] = Derivative(signal=signal, order=order, of=name)
    return derived


def recorded_signals(inputs: Mapping[str, Mapping[str, Any]], source: str = "run.json") -> dict[str, InputSignal]:
    """The signals a run recorded (run.json's ``inputs``, :class:`~fourbar_common.contract.run_record.RecordedInput`
    ``signal`` by name), to drive a replay as the run did.  A CSV column is read again from its
    recorded (absolute) path and must still have the recorded SHA-256.  Raises
    :class:`~orchestrator.validation.ConfigError` naming ``source`` and the field."""
    from .validation import ConfigError

    class _Reporter(ProblemReporter):
        def __init__(self):
            self.raw, self.problems = {}, []

    reporter = _Reporter()
    table = {}
    derived = {}
    for name, signal in inputs.items():
        signal = dict(signal)
        if signal.get("type") == Derivative.KIND:
            derived[name] = signal
            continue
        if signal.get("type") == "ramp" and "duration" in signal:
            signal.pop("to", None)          # recorded for readers; slope and duration define it
        if signal.get("type") == "csv":
            signal.pop("rows", None)
            signal.pop("sha256", None)
        table[name] = signal
    signals = parse_inputs(reporter, table, None, Path("/"), None)
    for name, signal in signals.items():
        want = inputs[name].get("sha256")
        if isinstance(signal, CsvColumn) and want is not None and signal.sha256 != want:
            reporter.problems.append(f"inputs.{name}.file = {show_value(signal.file)}: changed since the run "
                                     f"(SHA-256 {signal.sha256[:12]}..., the run read {str(want)[:12]}...)")
    for name, item in derived.items():
        of, order = item.get("of"), item.get("order")
        if of not in signals or order not in DRIVER_RATES:
            reporter.problems.append(f"inputs.{name}: the derivative of order {order!r} of {of!r}, which is not "
                                     f"a recorded signal (or not of order 1 or 2)")
        else:
            signals[name] = Derivative(signal=signals[of], order=order, of=of)
    if reporter.problems:
        raise ConfigError(source, reporter.problems)
    return signals


def parse_inputs(reporter: ProblemReporter, table: Any, inputs: Mapping[str, Any] | None, base_dir: Path,
                 span: tuple[float, float] | None, fmu_name: str = "the FMU") -> dict[str, InputSignal]:
    """The signals of a case file's ``[inputs]`` table, by input name; problems go to ``reporter``.

    ``inputs``: the FMU's input variables by name (FMPy's), None when the FMU could not be read
    (then names are not checked).  ``base_dir``: what a CSV file's path is relative to (the case
    file's folder).  ``span``: the run's (start, stop) in s, which a CSV file must cover.
    """
    if table is None:
        return {}
    if not isinstance(table, dict):
        reporter.problem("inputs", table, f"expected an [inputs] table (input name = signal), got {kind_of(table)}")
        return {}
    signals: dict[str, InputSignal] = {}
    for name, item in table.items():
        where = f"inputs.{name}"
        if inputs is not None:
            if name not in inputs:
                have = ", ".join(inputs) or "none (it declares no input variables)"
                reporter.problem(where, item, f"{fmu_name} has no input named {name!r}; its inputs: {have}")
                continue
            var = inputs[name]
            if var.type != "Real":
                reporter.problem(where, item, f"{name} is an {var.type} input; [inputs] drives Real inputs only")
                continue
        signal = _signal(reporter, where, item, base_dir, span)
        if signal is not None:
            signals[name] = signal
    return signals


def _signal(reporter: ProblemReporter, where: str, item: Any, base_dir: Path,
            span: tuple[float, float] | None) -> InputSignal | None:
    if isinstance(item, (int, float)) and not isinstance(item, bool):
        value = reporter.number(where, item)
        return Constant(value) if value is not None else None
    if not isinstance(item, dict):
        reporter.problem(where, item, f"expected a number (a constant) or a table with type = one of "
                                      f"{', '.join(map(repr, INPUT_TYPES))}, got {kind_of(item)}")
        return None
    kind = item.get("type")
    if kind is None:
        reporter.missing(f"{where}.type", f"one of {', '.join(map(repr, INPUT_TYPES))}")
        return None
    if kind not in INPUT_TYPES:
        reporter.problem(f"{where}.type", kind, f"expected one of {', '.join(map(repr, INPUT_TYPES))}")
        return None
    required, optional = INPUT_TYPES[kind]
    before = len(reporter.problems)
    reporter.unknown_keys(item, ("type", *required, *optional), where)
    for key in required:
        if key not in item:
            reporter.missing(f"{where}.{key}", _EXPECTED[key])
    if len(reporter.problems) > before:
        return None
    numbers: dict[str, float | None] = {}
    if kind not in ("table", "csv"):
        numbers = {k: reporter.number(f"{where}.{k}", item[k], "s" if k in _TIMES else "")
                   for k in (*required, *optional) if k in item}
    if any(v is None for v in numbers.values()):
        return None
    if kind == "constant":
        return Constant(numbers["value"])
    if kind == "step":
        return Step(before=numbers["before"], after=numbers["after"], time=numbers["time"])
    if kind == "ramp":
        return _ramp(reporter, where, numbers)
    if kind == "sine":
        if numbers["frequency"] < 0.0:
            reporter.problem(f"{where}.frequency", numbers["frequency"], "expected a frequency >= 0 Hz")
            return None
        return Sine(amplitude=numbers["amplitude"], frequency=numbers["frequency"],
                    phase=numbers.get("phase", 0.0), offset=numbers.get("offset", 0.0))
    if kind == "table":
        return _table(reporter, where, item["rows"])
    return _csv(reporter, where, item, base_dir, span)


_TIMES = ("time", "start", "duration")
_EXPECTED = {
    "value": "a number", "before": "the value before the step", "after": "the value from the step on",
    "time": "a time in s", "from": "the value before the ramp", "start": "the ramp's start time in s",
    "amplitude": "a number", "frequency": "a frequency in Hz",
    "rows": "an array of [time, value] rows, e.g. rows = [[0.0, 0.0], [1.0, 2.0]]",
    "file": "the CSV file's path, relative to the case file", "column": "the name of the CSV column of values",
}


def _ramp(reporter: ProblemReporter, where: str, numbers: dict[str, float]) -> Ramp | None:
    """A ramp from ``from`` at ``start``, given by two of ``to``, ``duration``, ``slope`` (or by
    ``slope`` alone: it never ends)."""
    given = [k for k in ("to", "duration", "slope") if k in numbers]
    if given not in (["to", "duration"], ["to", "slope"], ["duration", "slope"], ["slope"]):
        reporter.problems.append(f"{reporter.field(where)}: a ramp gives `to` and `duration`, `to` and `slope`, "
                                 f"`duration` and `slope`, or `slope` alone (a ramp that never ends); "
                                 f"got {', '.join(given) or 'none of them'}")
        return None
    start, v0 = numbers["start"], numbers["from"]
    duration, slope, to = numbers.get("duration"), numbers.get("slope"), numbers.get("to")
    if duration is not None and duration <= 0.0:
        reporter.problem(f"{where}.duration", duration, "expected a duration > 0 s")
        return None
    if given == ["slope"]:
        return Ramp(from_=v0, start=start, slope=slope)
    if duration is None:
        if slope == 0.0 or (to - v0) / slope <= 0.0:
            reporter.problem(f"{where}.slope", slope, f"expected a slope of the sign of to - from = {to - v0!r}, "
                                                      f"not 0 (it would never reach `to`)")
            return None
        duration = (to - v0) / slope
    if slope is None:
        slope = (to - v0) / duration
    if not math.isfinite(start + duration) or not math.isfinite(slope):
        reporter.problem(where, {k: numbers[k] for k in given}, "the ramp's end or slope is not a finite number")
        return None
    return Ramp(from_=v0, start=start, slope=slope, duration=duration)


def _table(reporter: ProblemReporter, where: str, rows: Any) -> Table | None:
    if not isinstance(rows, list) or not rows:
        reporter.problem(f"{where}.rows", rows, "expected a non-empty array of [time, value] rows")
        return None
    times: list[float] = []
    values: list[float] = []
    for i, row in enumerate(rows):
        at = f"{where}.rows[{i}]"
        if not isinstance(row, list) or len(row) != 2:
            reporter.problem(at, row, "expected a row [time in s, value]")
            return None
        t, v = reporter.number(at, row[0], "s"), reporter.number(at, row[1])
        if t is None or v is None:
            return None
        times.append(t)
        values.append(v)
    problem = _order_problem(times, values)
    if problem is not None:
        i, text = problem
        reporter.problem(f"{where}.rows[{i}]", rows[i], text)
        return None
    return Table(times=tuple(times), values=tuple(values))


def _order_problem(times: list[float], values: list[float]) -> tuple[int, str] | None:
    """(row index, what is wrong) when the times decrease, one time is given three times, or
    two rows are so close that the slope between them is not a finite number."""
    for i in range(1, len(times)):
        if times[i] > times[i - 1] and not math.isfinite((values[i] - values[i - 1]) / (times[i] - times[i - 1])):
            return i, (f"time {times[i]!r} s is so close to the previous row's {times[i - 1]!r} s that the slope "
                       f"between them is not a finite number; expected rows further apart, or one time twice (a step)")
        if times[i] < times[i - 1]:
            return i, f"time {times[i]!r} s is before the previous row's {times[i - 1]!r} s; expected times in order"
        if i >= 2 and times[i] == times[i - 1] == times[i - 2]:
            return i, (f"time {times[i]!r} s is given a third time; a time twice is a step (before, after), "
                       f"three times is ambiguous")
    return None


def _csv(reporter: ProblemReporter, where: str, item: dict, base_dir: Path,
         span: tuple[float, float] | None) -> CsvColumn | None:
    """The CSV file's time and value columns as a :class:`CsvColumn`; every problem named by
    file, row (the file's line number) and column."""
    file, column, time_column = item["file"], item["column"], item.get("time", "time")
    for key, value in (("file", file), ("column", column), ("time", time_column)):
        if not isinstance(value, str) or not value:
            reporter.problem(f"{where}.{key}", value, f"expected a non-empty string, got {kind_of(value)}")
            return None
    path = (base_dir / file).resolve()
    label = f"{where}.file = {show_value(file)} ({path})"
    try:
        with open_regular(path) as handle:
            data = handle.read(MAX_CSV_BYTES + 1)
    except FileNotFoundError:
        reporter.problems.append(f"{label}: file not found (relative to the case file's folder)")
        return None
    except NotRegularFileError as exc:
        reporter.problems.append(f"{label}: {exc.strerror}; expected a CSV file")
        return None
    except OSError as exc:
        reporter.problems.append(f"{label}: cannot read it: {exc.strerror or exc}")
        return None
    if len(data) > MAX_CSV_BYTES:
        reporter.problems.append(f"{label}: larger than {MAX_CSV_BYTES} bytes; expected a CSV of (time, value) rows")
        return None
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        reporter.problems.append(f"{label}: not UTF-8 text ({exc.reason} at byte {exc.start})")
        return None
    try:
        reader = csv.reader(io.StringIO(text, newline=""))
        header = next(reader, None)
        if header is None:
            reporter.problems.append(f"{label}: empty; expected a header row naming the columns, then rows")
            return None
        header = [h.strip() for h in header]
        missing = [c for c in (time_column, column) if c not in header]
        if missing:
            reporter.problems.append(f"{label}: no column named {', '.join(map(repr, missing))} in its header; "
                                     f"it has: {', '.join(map(repr, header))}")
            return None
        ti, vi = header.index(time_column), header.index(column)
        times: list[float] = []
        values: list[float] = []
        for row in reader:
            line = reader.line_num
            if not row or all(not c.strip() for c in row):
                continue
            cells = []
            for index, name in ((ti, time_column), (vi, column)):
                cell = row[index].strip() if index < len(row) else ""
                number = _decimal(cell)
                if number is None:
                    reporter.problems.append(f"{label}: line {line}, column {name!r}: {cell!r} is not a finite "
                                             f"number; expected decimal numbers only")
                    return None
                cells.append(number)
            times.append(cells[0])
            values.append(cells[1])
    except csv.Error as exc:
        reporter.problems.append(f"{label}: not readable as CSV at line {reader.line_num}: {exc}")
        return None
    if not times:
        reporter.problems.append(f"{label}: has a header but no rows")
        return None
    problem = _order_problem(times, values)
    if problem is not None:
        reporter.problems.append(f"{label}: data row {problem[0] + 1}, column {time_column!r}: {problem[1]}")
        return None
    if span is not None and (times[0] > span[0] or times[-1] < span[1]):
        reporter.problems.append(f"{label}: its {time_column!r} column runs from {times[0]!r} to {times[-1]!r} s, "
                                 f"which does not cover the run, {span[0]!r} to {span[1]!r} s; expected rows from "
                                 f"the start to the stop time")
        return None
    return CsvColumn(times=tuple(times), values=tuple(values), file=str(path), time_column=time_column,
                     column=column, sha256=hashlib.sha256(data).hexdigest())


def _decimal(cell: str) -> float | None:
    """A finite number written in decimal (``1``, ``-2.5``, ``3e-2``); None for anything else
    (``nan``, ``inf``, ``0x10``, empty)."""
    if not cell or not all(c in "0123456789+-.eE" for c in cell):
        return None
    try:
        value = float(cell)
    except ValueError:
        return None
    return value if math.isfinite(value) else None
