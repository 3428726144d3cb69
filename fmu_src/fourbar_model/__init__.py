"""Run-time part of the FourBar FMU: numpy/scipy only, shipped in the FMU's resources.

``equations`` is generated at build time by ``fmu_src/codegen.py``; ``dae`` integrates
the Lagrange-multiplier DAE with an explicit Runge-Kutta method.
"""
__all__ = ["dae"]
