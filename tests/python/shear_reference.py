"""An independent model of the three-storey shear frame, written from eq. (1) and the effect
definitions of the modelDescription, integrated with scipy's DOP853 at a tight tolerance.

    M ÿ + C ẏ + K y + g(y, ẏ) = φ u,   u = force − control_force,  φ = (1, 0, 0)

Storey s (s = 1, 2, 3) joins floor s − 1 (the ground for s = 1) to floor s; its drift is
δ_s = y_s − y_{s−1} and its spring and damper resist it with k_s δ_s + c_s δ̇_s. A storey force
f_s acts on floor s as −f_s and on floor s − 1 as +f_s. The effects, from their definitions:

- contact across storey s (`contactAB`, A = s − 1, B = s): no force while |δ_s| ≤ gap, a spring
  of the contact stiffness once the gap is closed: f = k_c (δ − gap) for δ > gap and
  k_c (δ + gap) for δ < −gap; side 1 keeps only the first branch (upper floor ahead), side −1
  only the second, side 0 both;
- cubic stiffness of storey s: f = k₃ δ_s³;
- friction on floor i: a force F_c tanh(ẏ_i / v_s) opposing the floor's velocity.
- discovered term i (`discovered{i}_*`, enabled): coefficient · f(x, v), f chosen by its code
  (the list in the description of `discovered{i}_function`), s = `discovered{i}_scale`. At a
  storey (placement 0) x and v are the storey's drift and drift rate and the force is a storey
  force like the spring's; at a floor (placement 1) they are the floor's displacement and
  velocity and the force resists them on that floor alone.

Nothing here comes from the FMU's source: only the parameter names and start values of its
modelDescription, which is the interface a user sees.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import solve_ivp

#: Tolerances of the reference: the FMU's RK4 errors are orders of magnitude above them
#: (checked: tightening rtol to 1e-12 moves the reference's NMSE by ~1e-11 %).
RTOL = 1e-10
ATOL = 1e-14


#: The discovered terms' functions by code, from the modelDescription: f(x, v, s).
DISCOVERED_FUNCTIONS = {
    1: ("x", lambda x, v, s: x),
    2: ("x^2", lambda x, v, s: x**2),
    3: ("x^3", lambda x, v, s: x**3),
    4: ("x|x|", lambda x, v, s: x * abs(x)),
    5: ("v", lambda x, v, s: v),
    6: ("v^2", lambda x, v, s: v**2),
    7: ("v|v|", lambda x, v, s: v * abs(v)),
    8: ("v^3", lambda x, v, s: v**3),
    9: ("sign(v)", lambda x, v, s: float(np.sign(v))),
    10: ("tanh(v/s)", lambda x, v, s: math.tanh(v / s)),
    11: ("max(0,x-s)", lambda x, v, s: max(0.0, x - s)),
    12: ("min(0,x+s)", lambda x, v, s: min(0.0, x + s)),
    13: ("x^2*v", lambda x, v, s: x**2 * v),
}


class Structure:
    """Parameters of eq. (1) and of the enabled effects, by the FMU's variable names."""

    def __init__(self, parameters: dict):
        p = parameters
        self.mass = np.array([p["m1"], p["m2"], p["m3"]], dtype=float)
        self.damping = np.array([p["c1"], p["c2"], p["c3"]], dtype=float)
        self.stiffness = np.array([p["k1"], p["k2"], p["k3"]], dtype=float)
        # (storey index 0..2, gap, stiffness, side)
        self.contacts = [
            (s, p[f"{name}_gap"], p[f"{name}_stiffness"], p[f"{name}_side"])
            for s, name in enumerate(("contact01", "contact12", "contact23"))
            if p[f"{name}_enabled"]
        ]
        self.cubics = [(s, p[f"cubic{s + 1}_stiffness"]) for s in range(3) if p[f"cubic{s + 1}_enabled"]]
        self.frictions = [
            (i, p[f"friction{i + 1}_force"], p[f"friction{i + 1}_velocity_scale"])
            for i in range(3)
            if p[f"friction{i + 1}_enabled"]
        ]
        # (function, placement 0 storey / 1 floor, index 0..2, coefficient, scale)
        self.discovered = [
            (
                DISCOVERED_FUNCTIONS[p[f"discovered{i}_function"]][1],
                p[f"discovered{i}_placement"],
                p[f"discovered{i}_at"] - 1,
                p[f"discovered{i}_coefficient"],
                p[f"discovered{i}_scale"],
            )
            for i in range(1, 7)
            if p.get(f"discovered{i}_enabled", False)
        ]

    @staticmethod
    def contact_force(drift: float, gap: float, stiffness: float, side: int) -> float:
        if side in (0, 1) and drift > gap:
            return stiffness * (drift - gap)
        if side in (0, -1) and drift < -gap:
            return stiffness * (drift + gap)
        return 0.0

    def acceleration(self, y: np.ndarray, v: np.ndarray, u: float) -> np.ndarray:
        drift = np.array([y[0], y[1] - y[0], y[2] - y[1]])
        drift_rate = np.array([v[0], v[1] - v[0], v[2] - v[1]])
        storey = self.stiffness * drift + self.damping * drift_rate
        for s, gap, stiffness, side in self.contacts:
            storey[s] += self.contact_force(drift[s], gap, stiffness, side)
        for s, cubic in self.cubics:
            storey[s] += cubic * drift[s] ** 3
        for function, placement, at, coefficient, scale in self.discovered:
            if placement == 0:
                storey[at] += coefficient * function(drift[at], drift_rate[at], scale)
        # Floor i feels −f of the storey below it and +f of the storey above it.
        resisting = np.array([storey[0] - storey[1], storey[1] - storey[2], storey[2]])
        for i, coulomb, velocity_scale in self.frictions:
            resisting[i] += coulomb * math.tanh(v[i] / velocity_scale)
        for function, placement, at, coefficient, scale in self.discovered:
            if placement == 1:
                resisting[at] += coefficient * function(y[at], v[at], scale)
        return (np.array([u, 0.0, 0.0]) - resisting) / self.mass


def simulate(structure: Structure, u0: float, values, slopes, step: float) -> dict:
    """Integrate from rest under u = values[k] + slopes[k]·(t − t_k) on each step [t_k, t_k+1].

    Each step is its own initial-value problem, so the solver never steps across the kinks of
    the input. The accelerations are evaluated at t_0 with u0 and at the end of each step with
    the input as it stands there, values[k] + slopes[k]·step: a master that records right
    after the step, before setting a new input, reads exactly that.
    """

    def rhs_for(value, slope):
        def rhs(tau, x):
            return np.concatenate((x[3:], structure.acceleration(x[:3], x[3:], value + slope * tau)))

        return rhs

    x = np.zeros(6)
    states = [x]
    accelerations = [structure.acceleration(x[:3], x[3:], u0)]
    for value, slope in zip(values, slopes):
        solution = solve_ivp(rhs_for(value, slope), (0.0, step), x, method="DOP853", rtol=RTOL, atol=ATOL)
        if not solution.success:
            raise RuntimeError(f"reference integration failed: {solution.message}")
        x = solution.y[:, -1]
        states.append(x)
        accelerations.append(structure.acceleration(x[:3], x[3:], value + slope * step))
    states = np.array(states)
    return {"acc": np.array(accelerations), "disp": states[:, :3], "vel": states[:, 3:]}
