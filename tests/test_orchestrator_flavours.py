"""The FMI layer's shape (issue 38, item 3): one class per FMI flavour behind one interface,
chosen once by ``orchestrator.instance.instance_for`` from the model description's FMI version
and the case's ``fmi_type``.  That every flavour runs a case like the others is shown on real
runs by tests/test_run_fmi3.py and tests/test_run_model_exchange.py; here: the choice, and the
refusals of what a flavour cannot do, on the shipped native FMUs (FMI 2.0 and 3.0, each with
both interfaces in one binary)."""
from __future__ import annotations

import numpy as np
import pytest

from orchestrator.case import describe_fmu
from orchestrator.instance import (FLAVOURS, Fmi2CoSimulation, Fmi2ModelExchange, Fmi3CoSimulation, Fmi3ModelExchange,
                                   FmuInstance, instance_for)

CHOICES = [("native", "CoSimulation", Fmi2CoSimulation), ("native", "ModelExchange", Fmi2ModelExchange),
           ("native3", "CoSimulation", Fmi3CoSimulation), ("native3", "ModelExchange", Fmi3ModelExchange)]


def test_every_flavour_has_its_class():
    assert set(FLAVOURS.values()) == {cls for _, _, cls in CHOICES}
    assert all(issubclass(cls, FmuInstance) for cls in FLAVOURS.values())


@pytest.mark.parametrize("kind, fmi_type, expected", CHOICES, ids=[f"{k}-{t}" for k, t, _ in CHOICES])
def test_the_factory_picks_the_flavour_and_it_steps(mechanism_fmus, kind, fmi_type, expected):
    """The chosen class runs: initialised, one step, the crank angle moved (theta2 starts at
    its start value; the four-bar swings under gravity, so 0.1 s moves it by far more than
    round-off)."""
    description = describe_fmu(mechanism_fmus.get("fourbar", kind))
    fmu = instance_for(description, "flavour", fmi_type=fmi_type)
    assert type(fmu) is expected and fmu.fmi_type == fmi_type
    with fmu:
        fmu.setup_experiment(0.0, 1.0, None)
        fmu.enter_initialization_mode()
        fmu.exit_initialization_mode()
        read = fmu.reader(["theta2"])
        before = read()[0]
        fmu.do_step(0.0, 0.1)
        assert abs(read()[0] - before) > 1e-6     # rad; the swing moves it ~1e-2 rad in 0.1 s


@pytest.mark.parametrize("kind, fmi_type", [("native", "ModelExchange"), ("native3", "CoSimulation")])
def test_only_fmi2_co_simulation_has_the_fast_loop(mechanism_fmus, kind, fmi_type):
    description = describe_fmu(mechanism_fmus.get("fourbar", kind))
    with instance_for(description, "fast", fmi_type=fmi_type) as fmu:
        with pytest.raises(ValueError, match=f"step_through drives an FMI 2.0 co-simulation instance; .* is run as "
                                             f"FMI {description.model.fmiVersion} {fmi_type}"):
            fmu.step_through([0.0, 0.1], ("theta2",), np.empty((1, 1)))


def test_an_unknown_interface_type_is_refused(mechanism_fmus):
    with pytest.raises(ValueError, match="fmi_type: expected one of CoSimulation, ModelExchange, got 'Scheduled'"):
        instance_for(describe_fmu(mechanism_fmus.get("fourbar", "native")), "x", fmi_type="Scheduled")
