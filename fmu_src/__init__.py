"""The mechanical part: the four-bar linkage as an FMI 2.0 co-simulation FMU.

- ``derivation.derive_equations``: M, Q, Phi, Phi_q, gamma from the Lagrangian (sympy).
- ``codegen.generate_module``: the equations as plain numpy code (what the FMU ships).
- ``fourbar_model``: the FMU's run-time package (numpy/scipy only): the DAE integrator.
- ``fourbar_slave.py``: the pythonfmu ``Fmi2Slave`` (the FMU's script, not imported here).
- ``build.build_fmu``: derive, generate, package with pythonfmu, complete and validate.

Attributes are imported on first use, so ``import fmu_src`` loads neither sympy nor pythonfmu.
"""
from importlib import import_module

__all__ = ["build_fmu", "derive_equations", "generate_module"]

_HOME = {"build_fmu": ".build", "derive_equations": ".derivation", "generate_module": ".codegen"}


def __getattr__(name):
    if name in _HOME:
        return getattr(import_module(_HOME[name], __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
