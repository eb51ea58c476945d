"""The shear FMU's discovered terms (`discovered{1..6}_*`) under fmpy 0.3.32: set through fmpy as
any parameter, run, and compared with the independent model of shear_reference.py, which
evaluates each term from the function codes listed in the modelDescription.

NMSE in percent per floor (acc1, acc2, acc3), on dataset1's force, the bar of the cross-check
in test_fmpy_shear.py. Measured with the FMU's 64 sub-steps:
  v|v| floor 2 + x^3 storey 3                     1.2e-12  1.4e-12  1.3e-12 (the terms change
                                                  the response by 123 %)
  ramps storey 2 + tanh floor 1 + x^2*v storey 1  2.5e-12  3.7e-12  1.1e-12 (95 %; the ramps'
                                                  bumper is closed at 60 of the 1024 samples)
"""

from __future__ import annotations

import fmpy
from fmpy.fmi1 import FMICallException
import numpy as np
import pytest

from shear_drive import (
    ACCELERATIONS,
    DISPLACEMENTS,
    STEP,
    assert_within,
    forward_slopes,
    instantiate,
    nmse,
    run_direct,
)
from shear_reference import DISCOVERED_FUNCTIONS, Structure, simulate
from test_fmpy_shear import EFFECT_NMSE_FLOOR, NMSE_BAR, _input_signal, _simulate_fmu


def term(index: int, function: str, placement: str, at: int, coefficient: float, scale: float = 1e-3) -> dict:
    """The FMU parameters of discovered term `index` (1-based), the function by its name."""
    code = next(code for code, (name, _) in DISCOVERED_FUNCTIONS.items() if name == function)
    return {
        f"discovered{index}_enabled": True,
        f"discovered{index}_function": code,
        f"discovered{index}_placement": {"storey": 0, "floor": 1}[placement],
        f"discovered{index}_at": at,
        f"discovered{index}_coefficient": coefficient,
        f"discovered{index}_scale": scale,
    }


#: A structure near the paper's priors, lightly damped, so the terms shape the response.
STRUCTURE = {
    **{f"m{i}": m for i, m in zip((1, 2, 3), (5.0, 5.2, 5.4))},
    **{f"c{i}": 0.05 for i in (1, 2, 3)},
    **{f"k{i}": k for i, k in zip((1, 2, 3), (4100.0, 3900.0, 4000.0))},
}

CASES = {
    # Quadratic air damping on floor 2 and a hardening storey 3: the brief's pair.
    "v|v| floor 2 + x^3 storey 3": {
        **STRUCTURE,
        **term(1, "v|v|", "floor", 2, 200.0),
        **term(2, "x^3", "storey", 3, 2e9),
    },
    # A bumper built from the two ramps on storey 2, smoothed friction on floor 1 and a
    # nonlinear damper on storey 1, in slots 3..6 (1 and 2 stay off).
    "ramps storey 2 + tanh floor 1 + x^2*v storey 1": {
        **STRUCTURE,
        **term(3, "max(0,x-s)", "storey", 2, 9000.0, scale=2e-4),
        **term(5, "min(0,x+s)", "storey", 2, 9000.0, scale=2e-4),
        **term(6, "tanh(v/s)", "floor", 1, 0.05, scale=2e-3),
        **term(4, "x^2*v", "storey", 1, 1e6),
    },
}


def _without_terms(parameters: dict) -> dict:
    return {name: value for name, value in parameters.items() if not name.startswith("discovered")}


def test_the_function_codes_are_the_ones_the_model_description_lists(shear_fmu):
    description = shear_fmu.variables["discovered1_function"].description
    listed = dict(entry.split(" ", 1) for entry in description.rsplit(": ", 1)[-1].split("; "))
    assert {int(code): name for code, name in listed.items()} == {
        code: name for code, (name, _) in DISCOVERED_FUNCTIONS.items()
    }, description
    variable = shear_fmu.variables["discovered1_function"]
    assert (int(variable.min), int(variable.max)) == (1, len(DISCOVERED_FUNCTIONS))


@pytest.mark.parametrize("case", list(CASES))
def test_discovered_terms_match_the_independent_model(case, shear_fmu, record, start_parameters):
    parameters = CASES[case]
    force = record.force
    reference = simulate(Structure({**start_parameters, **parameters}), force[0], force[:-1], forward_slopes(force), STEP)
    accelerations = run_direct(shear_fmu, parameters, force)
    error = nmse(reference["acc"], accelerations)
    print(f"{case}: NMSE {np.array2string(error, precision=3)} %")
    assert np.all(error < NMSE_BAR), f"{case}: NMSE per floor {np.array2string(error, precision=3)} %, bar {NMSE_BAR} %"

    # The terms shape the response, so a wrong or ignored law cannot pass.
    linear = run_direct(shear_fmu, _without_terms(parameters), force)
    effect = np.max(nmse(linear, accelerations))
    print(f"{case}: the terms change the response by {effect:.3g} %")
    assert effect > EFFECT_NMSE_FLOOR, f"{case}: the terms change the response by only {effect:.3g} %"


@pytest.mark.usefixtures("fmpy_input_derivatives_fixed")
def test_simulate_fmu_with_start_values_runs_the_terms(fmu_path, shear_fmu, record):
    """fmpy.simulate_fmu with the terms as start values, every sample given twice (the direct
    run's input, see test_fmpy_shear.py): the FMU2Slave run to 1e-9."""
    parameters = CASES["v|v| floor 2 + x^3 storey 3"]
    force = record.force
    time = np.concatenate(([-STEP], np.repeat(record.time, 2)))
    doubled = np.concatenate(([force[0]], np.repeat(force, 2)))
    by_fmpy = _simulate_fmu(
        fmu_path, _input_signal(time, doubled), record.time[-1], set_input_derivatives=True, start_values=parameters
    )
    assert_within(by_fmpy, run_direct(shear_fmu, parameters, force), 1e-9, "simulate_fmu with discovered terms")


def test_bad_values_are_refused_and_change_nothing(shear_fmu):
    """An unknown function code, a site outside 1..3, a placement other than 0 or 1 and a scale
    ≤ 0 return fmi2Error and leave the value as it was (the message naming the variable is
    checked on the Rust side, fmu-shear/src/effects/discovered.rs)."""
    slave = fmpy.fmi2.FMU2Slave(
        guid=shear_fmu.model_description.guid,
        unzipDirectory=str(shear_fmu.unzip_dir),
        modelIdentifier=shear_fmu.model_identifier,
        instanceName="refused",
    )
    slave.instantiate()
    try:
        # In initialization mode, where fixed parameters may be set: a refusal is the value's.
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.setInteger([shear_fmu.vr("discovered3_at")], [2])
        assert slave.getInteger([shear_fmu.vr("discovered3_at")]) == [2]
        for name, value in [
            ("discovered2_function", 14),
            ("discovered2_function", 0),
            ("discovered3_at", 0),
            ("discovered3_at", 4),
            ("discovered1_placement", 2),
            ("discovered6_scale", 0.0),
            ("discovered6_scale", -1e-3),
        ]:
            variable = shear_fmu.variables[name]
            getter, setter = {
                "Integer": (slave.getInteger, slave.setInteger),
                "Real": (slave.getReal, slave.setReal),
            }[variable.type]
            before = getter([variable.valueReference])
            with pytest.raises(FMICallException):
                setter([variable.valueReference], [value])
            assert getter([variable.valueReference]) == before, name
    finally:
        slave.freeInstance()


def test_fmu_state_carries_the_terms(shear_fmu, record):
    """A state serialized with the terms on continues in a fresh instance (terms off) exactly as
    the original does."""
    force = record.force
    slopes = forward_slopes(force)
    outputs = [shear_fmu.vr(name) for name in ACCELERATIONS + DISPLACEMENTS]
    force_vr = [shear_fmu.vr("force")]

    def steps(slave, first, last):
        rows = []
        for k in range(first, last):
            slave.setReal(force_vr, [force[k]])
            slave.setRealInputDerivatives(force_vr, [1], [slopes[k]])
            slave.doStep(k * STEP, STEP, noSetFMUStatePriorToCurrentPoint=False)
            rows.append(slave.getReal(outputs))
        return np.array(rows)

    parameters = CASES["v|v| floor 2 + x^3 storey 3"]
    original = instantiate(shear_fmu, parameters, force[0], "original")
    fresh = instantiate(shear_fmu, STRUCTURE, force[0], "fresh")
    try:
        steps(original, 0, 300)
        serialized = original.serializeFMUstate(original.getFMUstate())
        continuation = steps(original, 300, 600)
        fresh.setFMUstate(fresh.deSerializeFMUstate(serialized))
        np.testing.assert_array_equal(steps(fresh, 300, 600), continuation)
        assert fresh.getBoolean([shear_fmu.vr("discovered2_enabled")]) == [True]
        assert fresh.getInteger([shear_fmu.vr("discovered2_function")]) == [3]
        assert fresh.getReal([shear_fmu.vr("discovered1_coefficient")]) == [200.0]
    finally:
        for slave in (original, fresh):
            slave.terminate()
            slave.freeInstance()
