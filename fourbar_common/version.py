"""The installed version of fourbar-cosim, for ``--version``."""
from __future__ import annotations

__all__ = ["package_version"]

#: The version in pyproject.toml, used when the package is run from a source tree without installing.
SOURCE_VERSION = "0.1.0"


def package_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("fourbar-cosim")
    except PackageNotFoundError:
        return SOURCE_VERSION
