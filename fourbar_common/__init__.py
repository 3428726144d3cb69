"""Small helpers that every part of fourbar-cosim needs, so each has one home.

The three parts (``fmu_src``, ``orchestrator``, ``monitor``) never import each other; they
may all import this package, which imports nothing of theirs and only the standard library.
"""
from __future__ import annotations

from .files import replace_atomically, write_json_atomic
from .version import package_version

__all__ = ["package_version", "replace_atomically", "write_json_atomic"]
