"""Workarounds for two pythonfmu 0.7 defects that show when FMUs are loaded into a Python host.

Both symptoms are reported upstream in PythonFMU issue #228 (crash at process exit; the
wrong slave class on a second load).  Everything pythonfmu-specific in this project lives
here; FMUs that are not pythonfmu's are left alone.  Delete this module, and its calls in
:mod:`orchestrator.fmi_instance` and :mod:`orchestrator.fmi_versions`, when a pythonfmu release
fixes both: the tests in ``tests/test_orchestrator_pythonfmu_workarounds.py`` then pass with
the calls removed (the exit test's control run stops crashing too).

1. Crash at exit (Linux): :func:`install_exit_guard`, :func:`release_library`.
   pythonfmu's export library (the FMU's ``binaries/linux64/*.so``) keeps its interpreter
   helper in a static ``std::shared_ptr`` and resets that pointer again from an ELF
   destructor, the exported ``finalizePythonInterpreter``.  The library is never really
   unloaded (``dlclose`` leaves it mapped), so at process exit both run in this order: the
   C++ static destructor frees the helper, then the ELF destructor writes into the freed
   block.  glibc may notice and abort ("corrupted double-linked list", exit status 134)
   after the program has finished; whether it does depends on the heap layout.  Calling
   ``finalizePythonInterpreter`` while the statics are alive resets the pointer properly,
   and the second call at exit finds it empty.  It drops only the static's own reference:
   an instance still allocated (after fmi2Fatal nothing may be called, so it is never
   freed) keeps the helper alive.  With the interpreter owned by the host (FMPy, our
   tools), the helper never finalizes Python.

2. The wrong code on a second load: :func:`forget_other_fmu_modules`.
   A pythonfmu FMU's binary imports its slave script by module name (``resources/
   slavemodule.txt``) into the host's interpreter, with its ``resources/`` first on
   ``sys.path``.  Python caches modules by name, so once one FMU has been instantiated, a
   second FMU whose slave module has the same name (another build of FourBar.fmu) silently
   gets the first FMU's classes.  Just before instantiating, the cached slave module and
   every module loaded from another FMU's ``resources/`` are dropped from ``sys.modules``
   when that FMU's Python files differ (fingerprinted), so the import reads the new FMU's
   files.  Runs of the same FMU (a sweep's worker runs hundreds) keep the cache.
"""
from __future__ import annotations

import atexit
import ctypes
import hashlib
import os
import re
import sys
import threading
from pathlib import Path

__all__ = ["clean_message", "forget_other_fmu_modules", "install_exit_guard", "release_library",
           "release_loaded_libraries"]

_WRAPPER = re.compile(r"Fatal py exception encountered: \[\w+\] PyObject_CallMethod\s*")
_EXCEPTION = re.compile(r"^\w+(?:Error|Exception)\((['\"])(.*)\1\)\s*$", re.S)


def clean_message(text: str) -> str:
    """An FMU log message without pythonfmu's wrapper around a slave's exception.

    pythonfmu logs ``Fatal py exception encountered: [exitInitializationMode]
    PyObject_CallMethod\nValueError('...')``; what the user needs is the ``...``.
    Other messages are returned unchanged.
    """
    stripped = _WRAPPER.sub("", text)
    if stripped == text:
        return text
    match = _EXCEPTION.match(stripped.strip())
    return match.group(2) if match else stripped.strip()



_SYMBOL = "finalizePythonInterpreter"
_HOOK_LOCK = threading.Lock()
_HOOK_INSTALLED = False


def release_library(dll) -> bool:
    """Reset pythonfmu's static interpreter helper in one loaded FMU library (ctypes CDLL).

    Returns True if the library is a pythonfmu one (it exports the symbol).  Call it after
    fmi2FreeInstance (or instead of it after fmi2Fatal) and before unloading the library.
    """
    if dll is None or not sys.platform.startswith("linux"):
        return False
    try:
        function = getattr(dll, _SYMBOL)
    except AttributeError:
        return False
    function.restype = None
    function.argtypes = []
    function()
    return True


def _loaded_fmu_libraries() -> list[str]:
    """Paths of the shared libraries mapped in this process that sit in an FMU's binaries/."""
    try:
        with open("/proc/self/maps", encoding="utf-8", errors="replace") as fh:
            lines = fh.read().splitlines()
    except OSError:
        return []
    paths = []
    for line in lines:
        parts = line.split(None, 5)
        if len(parts) == 6:
            path = parts[5].strip()
            # FMPy removes the extracted FMU after a run: the mapping then reads "(deleted)",
            # and the loader still knows the library by its original name.
            path = path.removesuffix(" (deleted)")
            if path.endswith(".so") and f"{os.sep}binaries{os.sep}" in path and path not in paths:
                paths.append(path)
    return paths


def release_loaded_libraries() -> int:
    """``release_library`` for every pythonfmu FMU library loaded in this process.

    Covers FMUs loaded by other code (``fmpy.simulate_fmu``...).  Returns how many were
    released.  Only libraries that are already loaded are touched (RTLD_NOLOAD).
    """
    if not sys.platform.startswith("linux"):
        return 0
    count = 0
    for path in _loaded_fmu_libraries():
        try:
            dll = ctypes.CDLL(path, mode=os.RTLD_NOLOAD | os.RTLD_LAZY)
        except OSError:     # unmapped since /proc/self/maps was read, or not a library
            continue
        count += release_library(dll)
    return count


def install_exit_guard() -> None:
    """Run ``release_loaded_libraries`` when the interpreter exits (once per process).

    Python's atexit handlers run before the C library's exit handlers, i.e. while the
    FMU libraries' statics are still alive.
    """
    global _HOOK_INSTALLED
    with _HOOK_LOCK:
        if not _HOOK_INSTALLED:
            atexit.register(release_loaded_libraries)
            _HOOK_INSTALLED = True

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
