"""The units a block file may give: the mechanisms' (``mechanism_model.variables.UNITS``) and the
electrical and control units of the shipped components, as SI base-unit exponents (FMI's
``<BaseUnit>``).  A unit not here is refused by the loader (docs/components.md lists them)."""
from __future__ import annotations

from ..mechanism_model.variables import UNITS as MECHANISM_UNITS

__all__ = ["BLOCK_UNITS"]

#: name -> (SI base-unit exponents, [(display unit, factor)]).
BLOCK_UNITS = {
    **MECHANISM_UNITS,
    "V": ({"kg": "1", "m": "2", "s": "-3", "A": "-1"}, []),
    "A": ({"A": "1"}, []),
    "ohm": ({"kg": "1", "m": "2", "s": "-3", "A": "-2"}, []),
    "H": ({"kg": "1", "m": "2", "s": "-2", "A": "-2"}, []),
    "N.m/A": ({"kg": "1", "m": "2", "s": "-2", "A": "-1"}, []),
    "V.s/rad": ({"kg": "1", "m": "2", "s": "-2", "A": "-1", "rad": "-1"}, []),
    "V/rad": ({"kg": "1", "m": "2", "s": "-3", "A": "-1", "rad": "-1"}, []),
    "rad/(V.s)": ({"kg": "-1", "m": "-2", "s": "2", "A": "1", "rad": "1"}, []),
    "1/s": ({"s": "-1"}, []),
}
