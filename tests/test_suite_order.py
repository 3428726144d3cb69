"""The order conftest.py gives the suite's modules for two xdist workers (support.two_halves)."""
from __future__ import annotations

import random

from support import two_halves


def _split(modules: dict[str, tuple[float, int]]):
    order = two_halves(modules)
    total = sum(n for _c, n in modules.values())
    # where worksteal's first worker's share ends: the first half of the tests, by count
    seen, first = 0, []
    for name in order:
        if seen >= total // 2:
            break
        first.append(name)
        seen += modules[name][1]
    return order, first


def test_every_module_once_and_the_costs_dealt_evenly():
    rng = random.Random(5)
    modules = {f"tests/test_{i:02d}.py": (rng.choice((0.5, 2.0, 30.0, 120.0)), rng.randint(1, 40)) for i in range(60)}
    modules["tests/test_many.py"] = (60.0, 6000)            # a module of many cheap tests
    order, first = _split(modules)
    assert sorted(order) == sorted(modules)
    total = sum(c for c, _n in modules.values())
    first_cost = sum(modules[m][0] for m in first)
    # the first worker's share holds about half of the cost: within the costliest module's
    assert abs(first_cost - total / 2) <= max(c for c, _n in modules.values()), (first_cost, total)


def test_each_worker_starts_on_its_costliest_modules():
    modules = {"tests/test_a.py": (100.0, 2), "tests/test_b.py": (90.0, 3), "tests/test_c.py": (1.0, 200),
               "tests/test_d.py": (1.0, 200), "tests/test_e.py": (5.0, 1)}
    order = two_halves(modules)
    assert order[0] in ("tests/test_a.py", "tests/test_b.py")
    # the two slow modules are dealt one to each half, each at the start of its half
    half = order.index("tests/test_c.py") if order.index("tests/test_c.py") < order.index("tests/test_d.py") \
        else order.index("tests/test_d.py")
    slow_positions = sorted(order.index(m) for m in ("tests/test_a.py", "tests/test_b.py"))
    assert slow_positions[0] == 0 and slow_positions[1] > half
