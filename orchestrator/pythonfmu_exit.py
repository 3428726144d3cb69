"""Guard against a use-after-free at process exit in pythonfmu 0.7.0 FMUs (Linux).

pythonfmu's export library (the FMU's ``binaries/linux64/*.so``) keeps its interpreter
helper in a static ``std::shared_ptr`` and resets that pointer again from an ELF
destructor, the exported function ``finalizePythonInterpreter``.  The library is never
really unloaded (``dlclose`` leaves it mapped), so at process exit both run, in this
order: the C++ static destructor frees the helper, then the ELF destructor assigns to the
destroyed pointer and writes into the freed block.  glibc may notice later and abort
("corrupted double-linked list", exit status 134) after the program has finished, which
turns an interrupted ``fourbar-run`` (130) or a passing test run into a crash.  valgrind
shows it as "Invalid read ... in finalizePythonInterpreter ... block freed in
__run_exit_handlers, allocated by pythonfmu::createInstance"; whether glibc aborts depends
on the heap layout, so it comes and goes with unrelated changes (path lengths, env size).

Calling ``finalizePythonInterpreter`` while the library's statics are still alive resets
the pointer properly, and the second call at exit then finds it empty and does nothing.
It drops only the static's own reference: an instance that is still allocated (after
fmi2Fatal nothing may be called, so it is never freed) keeps the helper alive.  With the
interpreter owned by the host (FMPy, our tools), the helper never finalizes Python.

Nothing here is specific to the four-bar; FMUs that are not pythonfmu's lack the symbol
and are left alone.
"""
from __future__ import annotations

import atexit
import ctypes
import os
import sys
import threading

__all__ = ["release_library", "release_loaded_libraries", "install_exit_hook"]

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


def install_exit_hook() -> None:
    """Run ``release_loaded_libraries`` when the interpreter exits (once per process).

    Python's atexit handlers run before the C library's exit handlers, i.e. while the
    FMU libraries' statics are still alive.
    """
    global _HOOK_INSTALLED
    with _HOOK_LOCK:
        if not _HOOK_INSTALLED:
            atexit.register(release_loaded_libraries)
            _HOOK_INSTALLED = True
