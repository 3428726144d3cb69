"""The installed version of fourbar-cosim, for ``--version``."""
from __future__ import annotations

import argparse
import sys
from typing import Any

__all__ = ["VersionAction", "package_version"]

#: The version in pyproject.toml, used when the package is run from a source tree without installing.
SOURCE_VERSION = "0.1.0"


def package_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("fourbar-cosim")
    except PackageNotFoundError:
        return SOURCE_VERSION


class VersionAction(argparse.Action):
    """``--version``: print ``<prog> <version>`` and exit, as argparse's ``action="version"``,
    but look the version up only when asked (importlib.metadata costs every ``--help`` and
    every run about 50 ms otherwise)."""

    def __init__(self, option_strings: list[str], dest: str = argparse.SUPPRESS, default: Any = argparse.SUPPRESS,
                 help: str = "show program's version number and exit") -> None:
        super().__init__(option_strings=option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any,
                 option_string: str | None = None) -> None:
        sys.stdout.write(f"{parser.prog} {package_version()}\n")
        parser.exit()
