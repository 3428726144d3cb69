"""The mechanical part: any planar mechanism described in a file (Table 1's four-bar by default), as
FMUs: pythonfmu (FMI 2.0 co-simulation) and native C (FMI 2.0 and 3.0, co-simulation and model exchange).

- ``mechanism``: the description file (``description``), the sympy derivation of eq. (10)-(11)
  (``derivation``), the variable table (``table``), the generated Python (``python_code``) and
  the numerical checks before a build (``check``).  Build time only.
- ``mechanisms/``: the shipped mechanism files (fourbar.toml: Table 1's linkage, the default).
- ``mechanism_model``: the pythonfmu FMUs' run-time package (numpy/scipy only): the DAE
  integrator (``dae``) and the slave (``slave``).
- ``build.build_fmu``: derive, generate, package with pythonfmu, complete and validate.
- ``c_codegen`` / ``native/`` / ``native_build``: the same equations printed as C, the native FMU.
- ``fmi_hosts`` / ``fmi_flavours``: the FMUs run in other FMI hosts, and every FMI flavour against
  FMI 2.0 co-simulation, with their tolerances; ``fourbar_configurations``: four-bar case
  configurations drawn by rule.  Test and benchmark time only (tests and benchmarks/ share them).

Attributes are imported on first use, so ``import fmu_src`` loads neither sympy nor pythonfmu.
"""
from importlib import import_module

__all__ = ["build_fmu", "load_mechanism", "prepare_mechanism"]

_HOME = {"build_fmu": ".build", "load_mechanism": ".mechanism.description",
         "prepare_mechanism": ".mechanism.check"}


def __getattr__(name):
    if name in _HOME:
        return getattr(import_module(_HOME[name], __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
