"""A package's public names imported on first use (PEP 562), so importing the package is cheap.

A package lists where each public name lives and gets the module-level ``__getattr__`` and
``__dir__`` that import the name's module when the name is first asked for::

    _HOMES = {"replay": "session", "MonitorOptions": "options"}
    __getattr__, __dir__ = lazy_names(__name__, _HOMES)

``from monitor import replay`` then imports ``monitor.session`` and nothing else, and a
command's ``--help`` does not pay for what only its work needs (docs/benchmarks.md, start-up).
"""
from __future__ import annotations

import sys
from importlib import import_module
from typing import Any, Callable, Mapping

__all__ = ["lazy_names"]


def lazy_names(package: str, homes: Mapping[str, str]) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``__getattr__`` and ``__dir__`` for ``package``, whose name ``n`` lives in its module ``homes[n]``."""

    def __getattr__(name: str) -> Any:
        home = homes.get(name)
        if home is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(import_module(f".{home}", package), name)
        setattr(sys.modules[package], name, value)          # asked once: the next lookup is plain
        return value

    def __dir__() -> list[str]:
        module = sys.modules[package]
        return sorted(set(vars(module)) | set(getattr(module, "__all__", ())))

    return __getattr__, __dir__
