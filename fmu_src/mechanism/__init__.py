"""Mechanisms as data: a planar mechanism described in a TOML file, its equations derived
with sympy (build time only).  ``description`` reads and checks the file, ``derivation``
derives eq. (10)-(11) for it, ``check`` assembles it numerically to find what only numbers
show (redundant constraints, a mechanism that cannot be assembled)."""
