"""Let each pythonfmu FMU run its own Python code when several are loaded in one process.

A pythonfmu FMU's binary imports its slave script by module name (``resources/
slavemodule.txt``) into the host's interpreter, with its ``resources/`` put first on
``sys.path``.  Python caches modules by name, so once one FMU has been instantiated,
a second FMU whose slave module has the same name, for instance another build of
FourBar.fmu, silently gets the *first* FMU's classes and packages: it runs the other
build's code.  (FMPy extracts every run to a new directory, so even the same file loaded
twice runs the first extraction's modules, whose files are already deleted.)

``forget_other_fmu_modules`` is called just before instantiating: it removes from
``sys.modules`` the cached slave module and every module loaded from the same
``resources/`` directory when that directory is not the one of the FMU about to be
instantiated and its Python files differed.  The next import then reads the new FMU's own
files.  Instances that are still alive keep the objects they already hold.  Runs of the
same FMU (a sweep's worker runs hundreds) keep the cached modules: the Python files of each
extracted FMU are fingerprinted when it is instantiated.
"""
from __future__ import annotations

import hashlib
import os
import sys
from pathlib import Path

__all__ = ["forget_other_fmu_modules"]

#: Fingerprint of the Python files of each FMU resources/ directory instantiated so far.
_FINGERPRINTS: dict[str, str] = {}


def _fingerprint(resources: Path) -> str:
    digest = hashlib.sha256()
    for path in sorted(resources.rglob("*.py")):
        digest.update(str(path.relative_to(resources)).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def _inside(path: str | None, directories: tuple[str, ...]) -> bool:
    """Whether a module file lies in one of the directories (given with a trailing separator)."""
    return bool(path) and path.startswith(directories)


def _forms(directory: Path) -> tuple[str, ...]:
    """The directory as written and resolved, each ending in a separator (prefix tests)."""
    forms = {str(directory), os.path.realpath(directory)}
    return tuple(f.rstrip(os.sep) + os.sep for f in forms)


def forget_other_fmu_modules(unzip_dir) -> list[str]:
    """Drop cached modules of another pythonfmu FMU that would shadow this one's.

    ``unzip_dir`` is the extracted FMU about to be instantiated.  Returns the names of the
    modules removed (empty for FMUs that are not pythonfmu's, and on first use).
    """
    resources = Path(unzip_dir) / "resources"
    try:
        name = (resources / "slavemodule.txt").read_text(encoding="utf-8").strip()
    except OSError:
        return []              # not a pythonfmu FMU
    try:
        fingerprint = _fingerprint(resources)
    except OSError:
        fingerprint = ""
    _FINGERPRINTS[os.path.realpath(resources)] = fingerprint
    cached = sys.modules.get(name)
    origin = getattr(cached, "__file__", None) if cached is not None else None
    if not origin or _inside(origin, _forms(resources)):
        return []
    other = _forms(Path(origin).parent)
    if fingerprint and _FINGERPRINTS.get(os.path.realpath(Path(origin).parent)) == fingerprint:
        return []              # the same Python code: keep it
    removed = [key for key, module in list(sys.modules.items())
               if _inside(getattr(module, "__file__", None), other)]
    for key in removed:
        del sys.modules[key]
    return removed
