"""The published data of Andrews' squeezing mechanism (tests/data/andrews_reference.toml) is
transcribed right: the four chains that meet at the joint E (crank 1 and rod 2 from O, lever 3
from B, bodies 5 and 4 from A, bodies 7 and 6 from A) put E at the same place, at the published
initial values and at the published solution at t = 0.03 s.  A digit mistyped among the first
12 significant ones of an angle or of a chain's length (rr d ss zt e u zf xa ya xb yb) parts
them beyond the bound.  The spring's point (sc, sd), the masses and inertias are not in the
chains: the FMU's run against the reference solution checks them.

The chains, in the paper's coordinates (Hairer & Wanner, Sec. VII.7), with e(a) = (cos a, sin a):
    E = rr e(beta) - d e(beta + Theta)                        (O to F to E)
      = B + ss e(gamma - pi/2)                                 (lever 3 about B)
      = A + zt e(delta) + e e(Phi + delta - pi/2)              (5 about A, then 4)
      = A + u e(epsilon - pi/2) + zf e(Omega + epsilon)        (7 about A, then 6)
fmu_src/mechanisms/andrews_squeezer.toml maps them to body angles.
"""
from __future__ import annotations

import math
import tomllib
from pathlib import Path

import pytest

DATA = Path(__file__).resolve().parent / "data" / "andrews_reference.toml"
#: |E from one chain - E from another| (m): the published values have 16 digits (the initial
#: ones 30), so the chains meet to round-off of lengths ~0.05 m: measured 1.0e-17 m (initial),
#: 7.6e-17 m (t = 0.03).  A change of 1e-12 in an angle moves E by ~3e-14 m.
MEET = 1e-14


def _e(a: float) -> tuple[float, float]:
    return math.cos(a), math.sin(a)


def _chains(c: dict, q: dict) -> list[tuple[float, float]]:
    A, B = (c["xa"], c["ya"]), (c["xb"], c["yb"])
    b, th, g, ph, de, om, ep = (q[k] for k in ("beta", "Theta", "gamma", "Phi", "delta", "Omega", "epsilon"))
    half = math.pi / 2
    return [
        tuple(c["rr"] * x - c["d"] * y for x, y in zip(_e(b), _e(b + th))),
        tuple(p + c["ss"] * x for p, x in zip(B, _e(g - half))),
        tuple(p + c["zt"] * x + c["e"] * y for p, x, y in zip(A, _e(de), _e(ph + de - half))),
        tuple(p + c["u"] * x + c["zf"] * y for p, x, y in zip(A, _e(ep - half), _e(om + ep))),
    ]


@pytest.mark.parametrize("table", ["initial", "reference"])
def test_the_four_chains_meet_at_E(table):
    data = tomllib.loads(DATA.read_text())
    points = _chains(data["constants"], data[table])
    gap = max(math.dist(points[0], p) for p in points[1:])
    assert gap <= MEET, (table, points)


def test_the_reference_is_at_the_published_time_and_the_motor_has_turned_the_crank():
    data = tomllib.loads(DATA.read_text())
    assert data["reference"]["t"] == 0.03
    # the crank turns about 2.5 times in 0.03 s (beta from -0.06 to 15.8 rad)
    assert 15 < data["reference"]["beta"] - data["initial"]["beta"] < 17
