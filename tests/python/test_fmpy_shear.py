"""The shear FMU under fmpy 0.3.32: validation, the FMU driven step by step through
`fmpy.fmi2.FMU2Slave` against an independent model of eq. (1), `fmpy.simulate_fmu` and its
habits, and the FMU state through fmpy.

Figures quoted as "measured" were measured on dataset1's force with the FMU's RK4 at 8
sub-steps per 1/51.2 s step; NMSE is in percent, per floor (acc1, acc2, acc3).
"""

from __future__ import annotations

import math

import fmpy
import numpy as np
import pytest
from fmpy.validation import validate_fmu

from shear_drive import (
    ACCELERATIONS,
    DISPLACEMENTS,
    STEP,
    assert_within,
    forward_slopes,
    instantiate,
    nmse,
    run,
    run_direct,
)
from shear_reference import Structure, simulate

#: The bar of the cross-check against the independent model (percent, every floor).
NMSE_BAR = 0.05
#: Margin on a measured NMSE for the tighter regression bound: the runs are deterministic (same
#: binary, same seeds), so 3× leaves room for another CPU's or libm's rounding and little else.
MEASURED_MARGIN = 3.0


def _random_structure(rng: np.random.Generator) -> dict:
    """A structure around the paper's priors: m ~ U(4.5, 6) kg, log c ~ N(−4.605, 1), k ~ U(3000, 5000) N/m."""
    parameters = {}
    for i in (1, 2, 3):
        parameters[f"m{i}"] = float(rng.uniform(4.5, 6.0))
        parameters[f"c{i}"] = float(math.exp(rng.normal(-4.605, 1.0)))
        parameters[f"k{i}"] = float(rng.uniform(3000.0, 5000.0))
    return parameters


def _parameter_sets() -> dict:
    rng = np.random.default_rng(512)
    return {
        "prior-means": {},
        "random-1": _random_structure(rng),
        "random-2": _random_structure(rng),
        # The paper's bumper (9 N/mm, 0.5 mm) between floors 2 and 3, closing on either side.
        "contact23": {
            **_random_structure(rng),
            "contact23_enabled": True,
            "contact23_gap": 5e-4,
            "contact23_stiffness": 9000.0,
            "contact23_side": 0,
        },
        "friction1": {
            **_random_structure(rng),
            "friction1_enabled": True,
            "friction1_force": 0.1,
            "friction1_velocity_scale": 1e-3,
        },
        "cubic2": {**_random_structure(rng), "cubic2_enabled": True, "cubic2_stiffness": 1e9},
        # The same bumper with a 0.4 mm gap on a structure near the prior means: the gap is closed
        # at 199 of the 1024 samples (66 in "contact23"), measured on a converged run.
        "contact23-frequent": {
            **{f"m{i}": m for i, m in zip((1, 2, 3), (5.0, 5.2, 5.4))},
            **{f"c{i}": 0.01 for i in (1, 2, 3)},
            **{f"k{i}": 4000.0 for i in (1, 2, 3)},
            "contact23_enabled": True,
            "contact23_gap": 4e-4,
            "contact23_stiffness": 9000.0,
            "contact23_side": 0,
        },
    }


PARAMETER_SETS = _parameter_sets()

#: Worst-floor NMSE against the reference, measured with 8 RK4 sub-steps (floors 1, 2, 3):
#:   prior-means  4.9e-5  6.7e-5  3.7e-5
#:   random-1     2.6e-5  3.3e-5  1.5e-5
#:   random-2     9.0e-5  1.0e-4  5.7e-5
#:   contact23    2.2e-3  8.2e-3  5.1e-3
#:   friction1    9.0e-8  1.6e-7  4.5e-8
#:   cubic2       3.7e-5  5.2e-5  2.3e-5
#:   contact23-frequent   66     107     68  — far above the bar. The reference is converged
#:   there (rtol 1e-10 → 1e-12 changes it by 1e-7 %, a 1e-9 relative change of the force by
#:   7e-8 %) and the FMU converges to it as the sub-steps grow, slowly (worst floor, 16: 4.3 %,
#:   32: 0.55 %, 128: 0.089 %, 512: 2.4e-4 %, 2048: 8e-8 %): RK4 with fixed sub-steps loses its
#:   order at every closing and opening of the gap (a kink of the force), and 8 sub-steps are far
#:   too few once contact is frequent.
#:   No tighter bound for that case: it does not meet the bar.
MEASURED_NMSE_AT_8_SUBSTEPS = {
    "prior-means": 6.7e-5,
    "random-1": 3.3e-5,
    "random-2": 1.0e-4,
    "contact23": 8.2e-3,
    "friction1": 1.6e-7,
    "cubic2": 5.2e-5,
    "contact23-frequent": None,
}

#: Worst-floor NMSE between a run with the effect and the same structure without it, measured:
#: contact23 210 %, friction1 96 %, cubic2 162 %, contact23-frequent 168 %. The bound, an order
#: below, makes sure each effect shapes the response, so a wrong or ignored law cannot pass.
EFFECT_NMSE_FLOOR = 10.0

EFFECT_PREFIXES = ("contact", "cubic", "friction")


def _without_effects(parameters: dict) -> dict:
    return {name: value for name, value in parameters.items() if not name.startswith(EFFECT_PREFIXES)}


@pytest.fixture(scope="module")
def reference_runs(record, start_parameters):
    """The independent model's accelerations for each parameter set, computed once."""
    cache = {}

    def reference(case: str) -> np.ndarray:
        if case not in cache:
            structure = Structure({**start_parameters, **PARAMETER_SETS[case]})
            force = record.force
            cache[case] = simulate(structure, force[0], force[:-1], forward_slopes(force), STEP)["acc"]
        return cache[case]

    return reference


def test_validate_fmu_reports_no_problem(fmu_path):
    problems = validate_fmu(str(fmu_path))
    assert problems == [], "fmpy.validation.validate_fmu:\n" + "\n".join(problems)


@pytest.mark.parametrize("case", list(PARAMETER_SETS))
def test_direct_run_matches_the_independent_model(case, shear_fmu, record, reference_runs):
    parameters = PARAMETER_SETS[case]
    reference = reference_runs(case)

    # As shipped: the FMU's own number of sub-steps.
    accelerations = run_direct(shear_fmu, parameters, record.force)
    error = nmse(reference, accelerations)
    substeps = shear_fmu.start_value("substeps")
    assert np.all(error < NMSE_BAR), (
        f"{case}: NMSE per floor {np.array2string(error, precision=3)} % against the independent "
        f"model, bar {NMSE_BAR} %, with the FMU's default {substeps} RK4 sub-steps"
    )

    # Regression bound at the sub-step count the figures were measured with.
    measured = MEASURED_NMSE_AT_8_SUBSTEPS[case]
    if measured is not None:
        at_8 = nmse(reference, run_direct(shear_fmu, {**parameters, "substeps": 8}, record.force))
        assert np.all(at_8 < MEASURED_MARGIN * measured), (
            f"{case}: NMSE {np.array2string(at_8, precision=3)} % with 8 sub-steps, measured {measured} %"
        )

    if _without_effects(parameters) != parameters:
        linear = run_direct(shear_fmu, _without_effects(parameters), record.force)
        effect = np.max(nmse(linear, accelerations))
        assert effect > EFFECT_NMSE_FLOOR, f"{case}: the effect changes the response by only {effect:.3g} %"


def test_accelerations_see_a_force_set_after_the_step(shear_fmu):
    """acc1..3 depend directly on force (modelDescription <Outputs>): read after a new force is
    set, they must reflect it at once, ÿ₁ changing by ΔF / m₁ and the other floors not at all."""
    slave = instantiate(shear_fmu, {}, force0=0.3)
    try:
        slave.setRealInputDerivatives([shear_fmu.vr("force")], [1], [2.0])
        slave.doStep(0.0, STEP)
        acc = [shear_fmu.vr(name) for name in ACCELERATIONS]
        before = np.array(slave.getReal(acc))
        force_after_step = slave.getReal([shear_fmu.vr("force")])[0]
        slave.setReal([shear_fmu.vr("force")], [force_after_step + 1.0])
        after = np.array(slave.getReal(acc))
    finally:
        slave.terminate()
        slave.freeInstance()
    m1 = shear_fmu.start_value("m1")
    np.testing.assert_allclose(after - before, [1.0 / m1, 0.0, 0.0], rtol=1e-12, atol=1e-12)
    # With first-order interpolation the force at the end of the step is value + slope·step.
    assert force_after_step == pytest.approx(0.3 + 2.0 * STEP, rel=1e-15)


# ------------------------------------------------------------------------------------------------
# fmpy.simulate_fmu
#
# What fmpy 0.3.32 does for a co-simulation FMU (fmpy/simulation.py, simulateCS and Input):
#  - it steps from output point to output point, t_k = k·output_interval (step_size is ignored);
#  - at t_k it sets the input interpolated in the signal table at t_k and, with
#    set_input_derivatives, the slope of the table's segment that *ends* at t_k, (F_k − F_k−1)/h,
#    except at t_0, where it holds the first value with slope 0 (`i0 == 0` branch);
#  - after doStep it records the outputs at t_k+1 *before* setting the input of t_k+1.
# So over [t_k, t_k+1] the FMU sees F_k + (F_k − F_k−1)/h · (t − t_k), an extrapolation of the
# previous segment, and acc at t_k+1 is read with the force standing at 2F_k − F_k−1, not F_k+1.
# dataset1's force is broadband (sample-to-sample changes as large as the force), so the response
# differs from the direct run by tens of percent: a point-by-point comparison with the direct run
# would be meaningless. The tests below compare what can be compared:
#  1. simulate_fmu against FMU2Slave driven with exactly those habits: identical;
#  2. simulate_fmu against the independent model fed the same extrapolated input: the tolerance
#     band is the NMSE bar, the difference with the direct run is explained by the habits;
#  3. simulate_fmu given every sample twice (a "time event" at each knot, where fmpy takes the
#     value after the event and the slope of the segment *after* it): the direct run, to 1e-9.
# ------------------------------------------------------------------------------------------------


def _input_signal(time: np.ndarray, force: np.ndarray) -> np.ndarray:
    signal = np.zeros(len(time), dtype=[("time", np.float64), ("force", np.float64), ("control_force", np.float64)])
    signal["time"] = time
    signal["force"] = force
    return signal


def _simulate_fmu(fmu_path, signal, stop_time, outputs=ACCELERATIONS, **kwargs) -> np.ndarray:
    result = fmpy.simulate_fmu(
        str(fmu_path),
        input=signal,
        output=list(outputs),
        output_interval=STEP,
        stop_time=stop_time,
        **kwargs,
    )
    return np.stack([result[name] for name in outputs], axis=1)


def _fmpy_slopes(force: np.ndarray) -> np.ndarray:
    """The slope fmpy gives step k: that of the segment ending at t_k, none on the first step."""
    return np.concatenate(([0.0], np.diff(force)[:-1] / STEP))


def test_fmpy_0_3_32_cannot_set_input_derivatives_unaided(fmu_path, record):
    """fmpy 0.3.32's fixed nine-element derivative buffer (see conftest) breaks
    set_input_derivatives for this FMU. When an fmpy release fixes it, this test fails: then
    drop the `fmpy_input_derivatives_fixed` fixture."""
    with pytest.raises(ValueError, match="same size"):
        _simulate_fmu(fmu_path, _input_signal(record.time, record.force), record.time[-1], set_input_derivatives=True)


def test_simulate_fmu_is_the_direct_loop_with_fmpy_habits(fmpy_input_derivatives_fixed, fmu_path, shear_fmu, record):
    force = record.force
    by_fmpy = _simulate_fmu(fmu_path, _input_signal(record.time, force), record.time[-1], set_input_derivatives=True)
    assert by_fmpy.shape == (len(force), 3), "one row per sample, t_0 … t_1023"

    with_habits = run(shear_fmu, {}, force[0], force[:-1], _fmpy_slopes(force))
    # The same calls with the same arguments in the same order: measured bitwise equal.
    assert_within(by_fmpy, with_habits, 1e-12, "simulate_fmu against FMU2Slave with fmpy's habits")

    # The habits matter on this input: measured NMSE against the direct run 23.0, 20.8, 13.5 %.
    direct = run_direct(shear_fmu, {}, force)
    assert np.all(nmse(direct, by_fmpy) > 5.0), "fmpy's input reconstruction should differ from the direct run here"


def test_simulate_fmu_agrees_with_the_model_fed_fmpys_input(
    fmpy_input_derivatives_fixed, fmu_path, start_parameters, record
):
    """The band around the direct run that fmpy's habits open, computed by the independent model."""
    force = record.force
    signal = _input_signal(record.time, force)
    reference = simulate(Structure(start_parameters), force[0], force[:-1], _fmpy_slopes(force), STEP)["acc"]

    error = nmse(reference, _simulate_fmu(fmu_path, signal, record.time[-1], set_input_derivatives=True))
    assert np.all(error < NMSE_BAR), f"NMSE {np.array2string(error, precision=3)} % with the FMU's default sub-steps"

    # Measured 5.2e-5, 6.8e-5, 4.2e-5 % with 8 sub-steps.
    at_8 = _simulate_fmu(fmu_path, signal, record.time[-1], set_input_derivatives=True, start_values={"substeps": 8})
    error = nmse(reference, at_8)
    assert np.all(error < MEASURED_MARGIN * 6.8e-5), f"NMSE {np.array2string(error, precision=3)} %, measured 6.8e-5 %"


@pytest.mark.usefixtures("fmpy_input_derivatives_fixed")
def test_simulate_fmu_with_each_sample_given_twice_is_the_direct_run(fmu_path, shear_fmu, record):
    """Each sample given twice, plus one before t_0: fmpy sees a time event at every t_k and,
    taking the value and slope after it, applies F_k with slope (F_k+1 − F_k)/h, exactly the
    direct run's input; the knot at −h keeps t_0 out of fmpy's "hold the first value, slope 0"
    branch. The outputs recorded before the next input see F_k + slope·h, as the direct run's
    do. SPEC §5: fmpy and our master agree to 1e-9 on the same inputs at the same points.
    Measured: bitwise equal."""
    force = record.force
    time = np.concatenate(([-STEP], np.repeat(record.time, 2)))
    doubled = np.concatenate(([force[0]], np.repeat(force, 2)))
    outputs = ACCELERATIONS + DISPLACEMENTS
    signal = _input_signal(time, doubled)
    by_fmpy = _simulate_fmu(fmu_path, signal, record.time[-1], outputs, set_input_derivatives=True)
    direct = run_direct(shear_fmu, {}, force, outputs)
    assert_within(by_fmpy, direct, 1e-9, "simulate_fmu with every sample twice against the direct run")


# ------------------------------------------------------------------------------------------------
# FMU state through fmpy
# ------------------------------------------------------------------------------------------------


def test_fmu_state_round_trips_give_identical_continuations(shear_fmu, record):
    """getFMUstate/setFMUstate on one instance and serialize → deserialize into a fresh instance
    (default parameters, contact off) both continue exactly as the original did. The state must
    carry the parameters and effects too: the original runs with contact between floors 2 and 3."""
    force = record.force
    slopes = forward_slopes(force)
    parameters = {**PARAMETER_SETS["contact23"]}
    outputs = [shear_fmu.vr(name) for name in ACCELERATIONS + DISPLACEMENTS]
    force_vr = [shear_fmu.vr("force")]
    split, end = 400, 700

    def steps(slave, first, last):
        rows = []
        for k in range(first, last):
            slave.setReal(force_vr, [force[k]])
            slave.setRealInputDerivatives(force_vr, [1], [slopes[k]])
            slave.doStep(k * STEP, STEP, noSetFMUStatePriorToCurrentPoint=False)
            rows.append(slave.getReal(outputs))
        return np.array(rows)

    original = instantiate(shear_fmu, parameters, force[0], "original")
    fresh = instantiate(shear_fmu, {}, force[0], "fresh")
    try:
        steps(original, 0, split)
        state = original.getFMUstate()
        serialized = original.serializeFMUstate(state)
        assert isinstance(serialized, bytes) and len(serialized) > 0
        continuation = steps(original, split, end)

        original.setFMUstate(state)
        np.testing.assert_array_equal(steps(original, split, end), continuation)

        fresh_state = fresh.deSerializeFMUstate(serialized)
        fresh.setFMUstate(fresh_state)
        np.testing.assert_array_equal(steps(fresh, split, end), continuation)
        gap = shear_fmu.vr("contact23_gap")
        assert fresh.getReal([gap]) == original.getReal([gap])
        assert fresh.getBoolean([shear_fmu.vr("contact23_enabled")]) == [True]

        # Continuing from the deserialized state again, after more steps, lands on the same values:
        # the state is a value, not a reference to the instance it came from.
        fresh.setFMUstate(fresh_state)
        np.testing.assert_array_equal(steps(fresh, split, end), continuation)
        fresh.freeFMUstate(fresh_state)
        original.freeFMUstate(state)
    finally:
        for slave in (original, fresh):
            slave.terminate()
            slave.freeInstance()

    # Without the state, the fresh instance would have continued differently: the check can fail.
    unrelated = instantiate(shear_fmu, {}, force[0], "unrelated")
    try:
        steps(unrelated, 0, split)
        assert not np.array_equal(steps(unrelated, split, end), continuation)
    finally:
        unrelated.terminate()
        unrelated.freeInstance()
