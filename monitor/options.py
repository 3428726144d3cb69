"""Every setting of the monitor, in one place: defaults, choices, checks and help texts.

:class:`MonitorOptions` (what is computed) and :class:`FollowOptions` (how a growing file is
read) are frozen dataclasses.  Each field carries an :class:`Rule` in its metadata: the check
(:meth:`MonitorOptions.validated` collects every problem into one
:class:`~monitor.errors.OptionError`), the parser of a command-line value, and, for the
fields the command line exposes, the flag, the help text and the argument group.
:func:`add_arguments` builds the ``fourbar-monitor`` arguments from these fields, so the
command line and the Python API cannot disagree on a default, a choice or a message.

Which detector an option belongs to is part of its field too (``option(..., detector=...)``):
an option of one detector set to anything but its default while the other detector runs is
refused, with the same message from the command line, :func:`monitor.replay` and a sweep
file (:meth:`MonitorOptions.validated`; :func:`detector_options` lists them).
"""
from __future__ import annotations

import argparse
import math
from dataclasses import MISSING, asdict, dataclass, field, fields, replace
from typing import Any, Callable, Mapping

from .detectors import detector_class, detector_names
from .errors import OptionError
from .forecasters import MODELS

__all__ = ["DETECTOR", "FollowOptions", "MonitorOptions", "REFIT_POLICIES", "Rule", "add_arguments", "check_every",
           "detector_options", "merged", "split_signals"]

REFIT_POLICIES = ("none", "paper")


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


@dataclass(frozen=True)
class Rule:
    """What one option accepts.

    ``accepts(value)`` decides; ``expected`` is the phrase of the message ("expected
    <expected>, got <value>"); ``parse`` turns command-line text into a value (it may raise
    ``ValueError``); ``choices`` lists the accepted values of a choice.
    """

    accepts: Callable[[Any], bool]
    expected: str
    parse: Callable[[str], Any] = float
    choices: tuple[str, ...] | Callable[[], tuple[str, ...]] | None = None    # a callable: asked when used
    metavar: str | None = None

    def problem(self, name: str, value: Any) -> str | None:
        return None if self.accepts(value) else f"{name}: expected {self.expected}, got {value!r}"

    def argparse_type(self) -> Callable[[str], Any]:
        """An argparse ``type``: the message names the value once; argparse adds the flag."""
        def convert(text: str) -> Any:
            try:
                value = self.parse(text)
            except ValueError:
                value = None
            if value is None or not self.accepts(value):
                raise argparse.ArgumentTypeError(f"expected {self.expected}, got {text!r}")
            return value
        return convert


def positive(unit: str) -> Rule:
    return Rule(lambda v: _is_number(v) and v > 0, f"a positive number {unit}".rstrip())


def at_least(low: int) -> Rule:
    return Rule(lambda v: isinstance(v, int) and not isinstance(v, bool) and v >= low,
                f"an integer ≥ {low}", parse=int)


def choice(values: tuple[str, ...]) -> Rule:
    return Rule(lambda v: v in values, f"one of {', '.join(values)}", parse=str, choices=values)


class _RegisteredDetectors:
    """The message phrase of the detector option, naming the detectors registered when it is shown."""

    def __str__(self) -> str:
        return f"one of {', '.join(detector_names())}"


#: ``cusum``: the sequential detector (default); ``mae``: the paper's windowed-MAE rule; any other
#: registered detector (:mod:`monitor.detectors`).
DETECTOR = Rule(lambda v: isinstance(v, str) and v in detector_names(), _RegisteredDetectors(),  # type: ignore
                parse=str, choices=detector_names)


def _parse_threshold(text: str) -> float | str:
    return "auto" if text.strip().lower() == "auto" else float(text)


THRESHOLD = Rule(lambda v: v == "auto" or (_is_number(v) and v > 0),
                 "a positive number in the signal's units or 'auto'", parse=_parse_threshold,
                 metavar="LEVEL|auto")
TRAIN = Rule(lambda v: (isinstance(v, (tuple, list)) and len(v) == 2 and all(_is_number(x) for x in v)
                        and v[1] > v[0]),
             "START END with END > START (seconds)", metavar="START END")
def split_signals(value: str) -> tuple[str, ...]:
    """``"x2, y2"`` → ``("x2", "y2")``: the columns named by the ``signal`` option."""
    return tuple(part.strip() for part in str(value).split(","))


def _signals_ok(value: Any) -> bool:
    if not isinstance(value, str) or not value.strip():
        return False
    names = split_signals(value)
    return all(names) and "time" not in names and len(set(names)) == len(names)


SIGNAL = Rule(_signals_ok, "one column name or several separated by commas (not 'time', no repeats)", parse=str,
              metavar="COL[,COL...]")
RATE = Rule(lambda v: _is_number(v) and 1e-6 <= v <= 100, "a rate per hour in [1e-6, 100]")
NON_NEGATIVE = Rule(lambda v: _is_number(v) and v >= 0, "a number ≥ 0")
FRACTION = Rule(lambda v: isinstance(v, float) and 0.2 <= v <= 0.9, "a fraction in [0.2, 0.9]")
TIMEOUT = Rule(lambda v: _is_number(v) and v >= 0, "a number of seconds ≥ 0 (0 = no limit)")


def option(default: Any, rule: Rule, help: str = "", *, flag: str | None = None, group: str = "",
           detector: str | None = None) -> Any:
    """A dataclass field with its rule; ``flag`` exposes it on the command line; ``detector``
    names the one detector that uses it (None: every detector does)."""
    assert detector is None or detector in detector_names(), detector
    return field(default=default, metadata={"rule": rule, "help": help, "flag": flag, "group": group,
                                            "detector": detector})


@dataclass(frozen=True)
class _Checked:
    def validated(self):
        """Check every field; raise one :class:`OptionError` listing all problems."""
        problems = [p for f in fields(self) if (p := f.metadata["rule"].problem(f.name, getattr(self, f.name)))]
        if problems:
            raise OptionError(f"invalid {self._what}:\n  " + "\n  ".join(problems))
        return self._normalised()

    def _normalised(self):
        return self

    def as_dict(self) -> dict[str, Any]:
        d = asdict(self)
        return {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}


@dataclass(frozen=True)
class MonitorOptions(_Checked):
    """Every setting of what the monitor computes (units: seconds and the signal's unit).

    ``auto_k``, ``auto_floor``, ``auto_z`` and ``validation_fraction`` parametrise the auto
    threshold (:func:`monitor.detector.auto_threshold`); ``chunk_seconds`` is the forecast
    cache's chunk; ``history_points`` and ``evaluation_points`` bound the kept series.
    """

    _what = "monitor options"

    signal: str = option("x2", SIGNAL, "column(s) to monitor, e.g. x2 or x2,x3,y4 (monitored jointly)",
                         flag="--signal", group="model")
    train: tuple[float, float] = option((0.0, 9.0), TRAIN, "training window in s (the paper's: 0 9)",
                                        flag="--train", group="model")
    model: str = option("prophet", choice(MODELS), "prophet (the paper's) or harmonic (least-squares Fourier "
                        "series, fast)", flag="--model", group="model")
    order: int = option(30, at_least(1), "Fourier order of the model", flag="--order", group="model")
    detector: str = option("cusum", DETECTOR, "cusum: sequential detector on the phase-locked forecast "
                           "residuals, designed by --false-alarm-rate; mae: the paper's windowed MAE against a "
                           "threshold", flag="--detector", group="detection")
    false_alarm_rate: float = option(0.01, RATE, "cusum: false alarms per hour of data the detector is designed for",
                                     flag="--false-alarm-rate", group="detection", detector="cusum")
    design_shift: float = option(0.5, positive("in noise standard deviations"), "cusum: the mean shift, in noise "
                                 "standard deviations, the CUSUM is tuned to (reference k = shift/2)",
                                 flag="--design-shift", group="detection", detector="cusum")
    noise_floor: float = option(1e-3, NON_NEGATIVE, "cusum: smallest noise scale, as a fraction of the training "
                                "amplitude (the scale of a noise-free signal)", flag="--noise-floor", group="detection",
                                detector="cusum")
    guard: float = option(3.0, NON_NEGATIVE, "cusum: phase tracking learns only from data at least GUARD s old "
                          "and quiet since", flag="--guard", group="detection", detector="cusum")
    track_time: float = option(15.0, positive("of seconds"), "cusum: time constant of the phase tracker; phase "
                               "drifts slower than this are followed", flag="--track-time", group="detection",
                               detector="cusum")
    shape_time: float = option(60.0, NON_NEGATIVE, "cusum: time constant of the waveform-shape correction, learnt "
                               "like the phase from quiet data; shape changes slower than this are followed; 0 = "
                               "no correction", flag="--shape-time", group="detection", detector="cusum")
    clear_after: float = option(30.0, positive("of seconds"), "cusum: a latched alarm clears after this long "
                                "without a CUSUM crossing", flag="--clear-after", group="detection",
                                detector="cusum")
    tracker_block: float = option(1.0, positive("of seconds"), detector="cusum")
    rate_prior: float = option(3e-5, NON_NEGATIVE, detector="cusum")
    threshold: float | str = option("auto", THRESHOLD, "mae: MAE threshold in the signal's units, or 'auto' from the "
                                    "training data", flag="--threshold", group="detection", detector="mae")
    window: float = option(0.5, positive("of seconds"), "mae: evaluation window: the newest WINDOW s of data",
                           flag="--window", group="detection", detector="mae")
    every: float = option(0.1, positive("of seconds"), "evaluation cadence in s of data time (cusum: "
                          "the statistic is recorded at this cadence; it is updated at every sample)",
                          flag="--every", group="detection")
    persistence: int = option(2, at_least(1), "mae: consecutive evaluations above the threshold before an alarm",
                              flag="--persistence", group="detection", detector="mae")
    refit: str = option("none", choice(REFIT_POLICIES), "mae: none: fit once; paper: refit on the latest "
                        "--refit-samples samples until the first evaluation passes (the paper's policy)",
                        flag="--refit", group="detection", detector="mae")
    refit_samples: int = option(1000, at_least(32), "mae: samples per refit", flag="--refit-samples",
                                group="detection", detector="mae")
    max_refits: int = option(10, at_least(0), detector="mae")
    seed: int = option(0, at_least(0))
    auto_k: float = option(2.0, positive(""), detector="mae")
    auto_floor: float = option(0.01, NON_NEGATIVE, detector="mae")
    auto_z: float = option(4.0, positive(""), detector="mae")
    validation_fraction: float = option(2 / 3, FRACTION)
    chunk_seconds: float = option(20.0, positive("of seconds"))
    history_points: int = option(20000, at_least(100))
    evaluation_points: int = option(20000, at_least(100))

    @property
    def signals(self) -> tuple[str, ...]:
        return split_signals(self.signal)

    @property
    def detector_class(self) -> Any:
        """The :class:`~monitor.detector.Detector` subclass the ``detector`` option names (the
        option's one decoding, :func:`monitor.detectors.detector_class`)."""
        return detector_class(self.detector)

    def validated(self) -> "MonitorOptions":
        checked = super().validated()
        problems = list(checked.detector_class.option_problems(checked))
        for f in fields(checked):
            owner = f.metadata["detector"]
            value = getattr(checked, f.name)
            if owner is not None and owner != checked.detector and value != f.default:
                flag = f.metadata["flag"]
                problems.append(f"{f.name}: {value!r} is an option of detector {owner} only; detector "
                                f"{checked.detector} does not use it (leave {f.name}"
                                f"{' (' + flag + ')' if flag else ''} at its default {f.default!r}, or choose "
                                f"detector {owner})")
        if problems:
            raise OptionError("invalid monitor options:\n  " + "\n  ".join(problems))
        return checked

    def _normalised(self) -> "MonitorOptions":
        return replace(self, train=(float(self.train[0]), float(self.train[1])),
                       signal=",".join(split_signals(self.signal)))


@dataclass(frozen=True)
class FollowOptions(_Checked):
    """How :func:`monitor.follow` reads a growing file."""

    _what = "follow options"

    poll: float = option(0.2, positive("of seconds"), "with --follow: seconds between reads of the file",
                         flag="--poll", group="following")
    timeout: float = option(60.0, TIMEOUT, "with --follow: give up after this many seconds without the file or "
                            "without new rows when run.json does not say the run ended and its writer cannot "
                            "be checked; 0 = wait for ever", flag="--timeout", group="following")


def detector_options(detector: str) -> tuple[str, ...]:
    """The :class:`MonitorOptions` fields that only ``detector`` uses."""
    return tuple(f.name for f in fields(MonitorOptions) if f.metadata["detector"] == detector)


def check_every(every: float, sample_step: float, source: str) -> None:
    """Refuse an evaluation cadence shorter than the data's sample step (raises :class:`OptionError`).

    Between two samples neither detector's statistic changes, so a shorter ``every`` only
    repeats evaluations: 1e-9 s on a 0.01 s grid would be ten million per sample.
    ``sample_step`` is the median step of the training window; a relative 1e-6 allows for
    the rounding of the file's times.
    """
    if every < sample_step * (1.0 - 1e-6):
        raise OptionError(f"{source}: every (--every) = {every!r} s is shorter than the data's sample step "
                          f"{sample_step:.6g} s; expected every ≥ {sample_step:.6g} s (between two samples the "
                          "statistic does not change: a shorter cadence only repeats evaluations)")


def merged(base: Any, settings: Mapping[str, Any]) -> Any:
    """``base`` with ``settings`` (field names) applied, validated; unknown names are an error."""
    known = [f.name for f in fields(base)]
    unknown = sorted(set(settings) - set(known))
    if unknown:
        raise OptionError(f"unknown {base._what[:-1]}(s): {', '.join(unknown)}; known: {', '.join(known)}")
    values = dict(settings)
    if isinstance(values.get("train"), list):
        values["train"] = tuple(values["train"])
    return replace(base, **values).validated()


def add_arguments(groups: Mapping[str, Any], cls: type) -> None:
    """Add the command-line arguments of ``cls``'s flagged fields to the argparse ``groups``."""
    for f in fields(cls):
        flag = f.metadata.get("flag")
        if not flag:
            continue
        rule: Rule = f.metadata["rule"]
        default = f.default if f.default is not MISSING else None
        shown = " ".join(map(str, default)) if isinstance(default, tuple) else default
        kwargs: dict[str, Any] = {"dest": f.name, "default": default,
                                  "help": f"{f.metadata['help']} (default: {shown})"}
        if isinstance(default, tuple):
            kwargs.update(nargs=len(default), metavar=tuple(rule.metavar.split()),
                          type=Rule(_is_number, "a finite time in seconds").argparse_type())
        elif rule.choices:
            kwargs.update(choices=rule.choices() if callable(rule.choices) else rule.choices)
        else:
            kwargs.update(type=rule.argparse_type(), metavar=rule.metavar)
        groups[f.metadata["group"]].add_argument(flag, **kwargs)
