"""The pythonfmu FMUs' run-time package (numpy and scipy only): the integrator of any
mechanism's DAE (``dae``), the variable type (``variables``) and, in a built FMU, the
mechanism's generated ``equations`` module."""
