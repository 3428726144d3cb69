"""The registry of detectors: the ``detector`` option's values and the classes they name.

This is the one place where the option is decoded (:func:`detector_class`;
:attr:`MonitorOptions.detector_class <monitor.options.MonitorOptions.detector_class>` calls
it).  The built-in detectors are registered here; another one registers itself with
:func:`register` from its own module (docs/monitor.md, "Adding a detector")::

    class Ewma(Detector):
        name, label = "ewma", "EWMA"
        Settings = EwmaSettings       # its own settings: a frozen DetectorSettings dataclass
        ...
    register(Ewma)
"""
from __future__ import annotations

from .cusum_detector import CusumDetector
from .detector import Detector
from .errors import OptionError
from .mae import MaeDetector
from .page_hinkley import PageHinkleyDetector

__all__ = ["detector_class", "detector_names", "register", "unregister"]

_REGISTRY: dict[str, type[Detector]] = {}


def register(cls: type[Detector]) -> type[Detector]:
    """Make ``cls`` available as ``detector=cls.name``; returns ``cls`` (usable as a decorator)."""
    if not (isinstance(cls, type) and issubclass(cls, Detector)):
        raise TypeError(f"register: expected a subclass of monitor.detector.Detector, got {cls!r}")
    if not cls.name or not cls.label:
        raise ValueError(f"register: {cls.__name__} needs the class attributes name and label")
    known = _REGISTRY.get(cls.name)
    if known is not None and known is not cls:
        raise ValueError(f"register: detector name {cls.name!r} is taken by {known.__name__}")
    _REGISTRY[cls.name] = cls
    return cls


def unregister(name: str) -> None:
    """Remove a registered detector (tests that register their own use it to clean up)."""
    if name in _BUILT_IN:
        raise ValueError(f"unregister: {name!r} is a built-in detector")
    _REGISTRY.pop(name, None)


def detector_names() -> tuple[str, ...]:
    """The accepted values of the ``detector`` option, built-ins first."""
    return tuple(_REGISTRY)


def detector_class(name: str) -> type[Detector]:
    """The class registered as ``name`` (raises :class:`~monitor.errors.OptionError` for an unknown name)."""
    try:
        return _REGISTRY[name]
    except (KeyError, TypeError):
        raise OptionError(f"detector: expected one of {', '.join(_REGISTRY)}, got {name!r}") from None


for _cls in (CusumDetector, MaeDetector, PageHinkleyDetector):      # the default first
    register(_cls)
_BUILT_IN = frozenset(_REGISTRY)
