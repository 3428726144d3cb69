"""What every detector shares, in one place: defaults, choices, checks and help texts.

:class:`MonitorOptions` (what is computed, whatever the detector) and :class:`FollowOptions`
(how a growing file is read) are frozen dataclasses of :func:`~monitor.option_rules.option`
fields (:mod:`monitor.option_rules`: the rule, the parser of a command-line value, the flag,
help text and argument group).  What only one detector uses is that detector's own
``Settings`` class (:class:`~monitor.option_rules.DetectorSettings`; ``CusumDetector.Settings``,
``MaeDetector.Settings``, ...): :class:`MonitorOptions` takes those settings as keywords too
(``MonitorOptions(detector="mae", window=0.3)``), keeps them as given and hands the running
detector its typed settings (:attr:`MonitorOptions.settings`).  :func:`add_arguments` builds the
``fourbar-monitor`` arguments from these declarations and from every registered detector's own,
so the command line, the Python API and sweep files cannot disagree on a default, a choice or
a message.

A setting of one detector set to anything but its default while another detector runs is
refused, with the same message from the command line, :func:`monitor.replay` and a sweep
file (:meth:`MonitorOptions.validated`; :func:`detector_options` lists a detector's settings).
"""
from __future__ import annotations

from dataclasses import MISSING, Field, dataclass, field, fields, replace
from typing import Any, Mapping

from .detectors import detector_class, detector_names
from .errors import OptionError
from .forecasters import forecaster_names
from .option_rules import (FRACTION, Checked, Rule, at_least, choice, is_number, option,
                           positive)

__all__ = ["DETECTOR", "FollowOptions", "MonitorOptions", "Rule", "add_arguments", "check_every", "detector_options",
           "merged", "option_default", "option_names", "split_signals"]
_is_number = is_number

#: ``cusum``: the sequential detector (default); ``mae``: the paper's windowed-MAE rule; any other
#: registered detector (:mod:`monitor.detectors`).
DETECTOR = choice(detector_names)


TRAIN = Rule(lambda v: (isinstance(v, (tuple, list)) and len(v) == 2 and all(_is_number(x) for x in v)
                        and v[1] > v[0]),
             "START END with END > START (seconds)", metavar="START END")


def split_signals(value: str) -> tuple[str, ...]:
    """``"x2, y2"`` → ``("x2", "y2")``: the columns named by the ``signal`` option."""
    return tuple(part.strip() for part in str(value).split(","))


def _signals_ok(value: Any) -> bool:
    if value == "":                  # the run's default (monitor.session.run_signal)
        return True
    if not isinstance(value, str) or not value.strip():
        return False
    names = split_signals(value)
    return all(names) and "time" not in names and len(set(names)) == len(names)


SIGNAL = Rule(_signals_ok, "one column name or several separated by commas (not 'time', no repeats)", parse=str,
              metavar="COL[,COL...]")
TIMEOUT = Rule(lambda v: _is_number(v) and v >= 0, "a number of seconds ≥ 0 (0 = no limit)")


def _detector_fields() -> dict[str, tuple[str, Field]]:
    """Every registered detector's own settings: name → (the detector's name, its field)."""
    found: dict[str, tuple[str, Field]] = {}
    for name in detector_names():
        for f in fields(detector_class(name).Settings):
            found.setdefault(f.name, (name, f))
    return found


@dataclass(frozen=True, init=False)
class MonitorOptions(Checked):
    """Every setting of what the monitor computes that every detector shares (units: seconds and
    the signal's unit), plus the settings given for the detectors (``given``).

    ``MonitorOptions(**values)`` takes the fields below and any registered detector's own
    settings by name (``clear_after=2.0``, ``window=0.3``); an unknown name is a
    ``TypeError``.  :attr:`settings` is the running detector's typed settings.
    ``validation_fraction`` is the held-out part of the training window (both built-ins);
    ``chunk_seconds`` is the forecast cache's chunk; ``history_points`` and
    ``evaluation_points`` bound the kept series.  ``signal=""`` (the default) stands for the run's
    default signal, which :func:`monitor.replay` and :func:`monitor.follow` fill in before
    monitoring (:func:`monitor.session.run_signal`: x2 for the four-bar).
    """

    _what = "monitor options"

    signal: str = option("", SIGNAL, "column(s) to monitor, e.g. x2 or x2,x3,y4 (monitored jointly); default: the "
                         "run's first output column (the exchange file's first column after time, else run.json's "
                         "first recorded output: x2 for the four-bar; a system run's first case output, its columns "
                         "named component.variable, e.g. motor.current)", flag="--signal", group="model")
    train: tuple[float, float] = option((0.0, 9.0), TRAIN, "training window in s (the paper's: 0 9)",
                                        flag="--train", group="model")
    model: str = option("prophet", choice(forecaster_names), "prophet (the paper's) or harmonic (least-squares "
                        "Fourier series, fast)", flag="--model", group="model")
    order: int = option(30, at_least(1), "Fourier order of the model", flag="--order", group="model")
    detector: str = option("cusum", DETECTOR, "cusum: sequential detector on the phase-locked forecast "
                           "residuals, designed by --false-alarm-rate; mae: the paper's windowed MAE against a "
                           "threshold; page-hinkley: Page–Hinkley test on the forecast residuals, designed by "
                           "--ph-false-alarm-rate", flag="--detector", group="detection")
    every: float = option(0.1, positive("of seconds"), "evaluation cadence in s of data time (cusum: "
                          "the statistic is recorded at this cadence; it is updated at every sample)",
                          flag="--every", group="detection")
    seed: int = option(0, at_least(0))
    validation_fraction: float = option(2 / 3, FRACTION)
    chunk_seconds: float = option(20.0, positive("of seconds"))
    history_points: int = option(20000, at_least(100))
    evaluation_points: int = option(20000, at_least(100))
    #: the detectors' own settings given, as sorted (name, value) pairs (read them through :attr:`settings`)
    given: tuple[tuple[str, Any], ...] = field(default=())

    def __init__(self, **values: Any):
        given = dict(values.pop("given", ()))
        for f in fields(self):
            if f.name != "given":
                object.__setattr__(self, f.name, values.pop(f.name, f.default))
        if values:
            owned = _detector_fields()
            unknown = [name for name in values if name not in owned]
            if unknown:
                raise TypeError(f"MonitorOptions.__init__() got an unexpected keyword argument {unknown[0]!r}")
            given.update(values)
        object.__setattr__(self, "given", tuple(sorted(given.items())))

    def __repr__(self) -> str:
        shown = ", ".join(f"{f.name}={getattr(self, f.name)!r}" for f in fields(self) if f.name != "given")
        return f"MonitorOptions({shown}{''.join(f', {k}={v!r}' for k, v in self.given)})"

    @property
    def signals(self) -> tuple[str, ...]:
        return split_signals(self.signal)

    @property
    def detector_class(self) -> Any:
        """The :class:`~monitor.detector.Detector` subclass the ``detector`` option names (the
        option's one decoding, :func:`monitor.detectors.detector_class`)."""
        return detector_class(self.detector)

    @property
    def settings(self) -> Any:
        """The running detector's own settings (an instance of its ``Settings`` class, from the
        values given and its defaults)."""
        cls = self.detector_class.Settings
        own = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in self.given if k in own})

    def value(self, name: str) -> Any:
        """The value of option ``name``: a shared field, or a detector's setting (given, else its default)."""
        if name in self.__dataclass_fields__ and name != "given":
            return getattr(self, name)
        return dict(self.given).get(name, _detector_fields()[name][1].default)

    def problems(self) -> list[str]:
        problems = super().problems()
        given = dict(self.given)
        for name, (_, f) in _detector_fields().items():       # in the detectors' declaration order
            problem = f.metadata["rule"].problem(name, given[name]) if name in given else None
            if problem:
                problems.append(problem)
        return problems

    def validated(self) -> "MonitorOptions":
        checked = super().validated()
        problems = list(checked.detector_class.option_problems(checked))
        given = dict(checked.given)
        for name, (owner, f) in _detector_fields().items():
            value = given.get(name, f.default)
            if owner != checked.detector and value != f.default:
                flag = f.metadata["flag"]
                problems.append(f"{name}: {value!r} is an option of detector {owner} only; detector "
                                f"{checked.detector} does not use it (leave {name}"
                                f"{' (' + flag + ')' if flag else ''} at its default {f.default!r}, or choose "
                                f"detector {owner})")
        if problems:
            raise OptionError("invalid monitor options:\n  " + "\n  ".join(problems))
        return checked

    def _normalised(self) -> "MonitorOptions":
        return replace(self, train=(float(self.train[0]), float(self.train[1])),
                       signal=",".join(split_signals(self.signal)) if self.signal else "")

    def as_dict(self) -> dict[str, Any]:
        """Every option by name: the shared fields, then each registered detector's settings
        (given, else their defaults), as summary.json records them."""
        d = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "given"}
        d.update({name: self.value(name) for name in _detector_fields()})
        return {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}


@dataclass(frozen=True)
class FollowOptions(Checked):
    """How :func:`monitor.follow` reads a growing file."""

    _what = "follow options"

    poll: float = option(0.2, positive("of seconds"), "with --follow: seconds between reads of the file",
                         flag="--poll", group="following")
    timeout: float = option(60.0, TIMEOUT, "with --follow: give up after this many seconds without the file or "
                            "without new rows when run.json does not say the run ended and its writer cannot "
                            "be checked; 0 = wait for ever", flag="--timeout", group="following")


def detector_options(detector: str) -> tuple[str, ...]:
    """The settings that only ``detector`` uses (its ``Settings`` fields)."""
    return tuple(f.name for f in fields(detector_class(detector).Settings))


def option_names() -> tuple[str, ...]:
    """Every option :class:`MonitorOptions` takes: the shared fields, then each registered detector's."""
    return tuple(f.name for f in fields(MonitorOptions) if f.name != "given") + tuple(_detector_fields())


def option_default(name: str) -> Any:
    """The default of option ``name`` (a shared field or a registered detector's setting)."""
    return MonitorOptions().value(name)


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
    """``base`` with ``settings`` (option names) applied, validated; unknown names are an error."""
    known = list(option_names()) if isinstance(base, MonitorOptions) else [f.name for f in fields(base)]
    unknown = sorted(set(settings) - set(known))
    if unknown:
        raise OptionError(f"unknown {base._what[:-1]}(s): {', '.join(unknown)}; known: {', '.join(known)}")
    values = dict(settings)
    if isinstance(values.get("train"), list):
        values["train"] = tuple(values["train"])
    return replace(base, **values).validated()


def _option_fields(cls: type) -> list[Field]:
    """``cls``'s option fields; for :class:`MonitorOptions` every registered detector's settings
    follow the ``detector`` field."""
    out: list[Field] = []
    for f in fields(cls):
        if f.name == "given":
            continue
        out.append(f)
        if cls is MonitorOptions and f.name == "detector":
            out.extend(f for _, f in _detector_fields().values())
    return out


def add_arguments(groups: Mapping[str, Any], cls: type) -> None:
    """Add the command-line arguments of ``cls``'s flagged fields to the argparse ``groups``
    (for :class:`MonitorOptions`: with every registered detector's own flagged settings)."""
    for f in _option_fields(cls):
        flag = f.metadata.get("flag")
        if not flag:
            continue
        rule: Rule = f.metadata["rule"]
        default = f.default if f.default is not MISSING else None
        shown = " ".join(map(str, default)) if isinstance(default, tuple) else default
        said = f" (default: {shown})" if shown != "" else ""        # "": the help says what the default is
        kwargs: dict[str, Any] = {"dest": f.name, "default": default, "help": f"{f.metadata['help']}{said}"}
        if isinstance(default, tuple):
            kwargs.update(nargs=len(default), metavar=tuple(rule.metavar.split()),
                          type=Rule(_is_number, "a finite time in seconds").argparse_type())
        elif rule.choices:
            kwargs.update(choices=rule.choices() if callable(rule.choices) else rule.choices)
        else:
            kwargs.update(type=rule.argparse_type(), metavar=rule.metavar)
        groups[f.metadata["group"]].add_argument(flag, **kwargs)
