#!/usr/bin/env python3
"""`twin diagnose` against an fmpy + scipy peer doing the same diagnosis computation, in the same
run: the peer is what a user without `twin diagnose` would write, the shear FMU driven through
fmpy's `FMU2Slave` and every fit a `scipy.optimize.least_squares`.

The computation (orchestrator/src/workflows/: diagnose/mod.rs, calibrate/mod.rs, diagnose/candidate.rs),
mirrored step by step:

- the twin: the physics parameters and the noise variances of the calibrated twin, read from the
  SSP (resources/physics.ssv, resources/twin.ssv); the FMU is target/fmu/fmu_shear.fmu (the same
  binary the SSP embeds);
- a simulation: one `FMU2Slave`, reset → setupExperiment(t0) → initialization mode, the twin's
  parameters, then the estimated ones → for each sample k: set the force F_k, read the outputs,
  then (k < n−1) the input derivative (F_{k+1} − F_k)/dt if the FMU canInterpolateInputs, and
  doStep(t_k, dt) — calibrate/simulator.rs's convention; a refused call or a non-finite output
  makes the parameters "refused". The 1024-step loop calls FMU2Slave's fmi2SetReal, fmi2GetReal,
  fmi2SetRealInputDerivatives and fmi2DoStep attributes (fmpy's status-checked wrappers of the
  C functions) with ctypes buffers made once per run: 2.2× faster than its convenience methods
  (setReal, getReal, …, which build new ctypes arrays at every call; --plain-api uses them), so
  that the peer is not slowed by an avoidable habit. Python's ~4,000 calls a record still cost
  more than the FMU's own work (the bench prints the milliseconds per simulation of both sides);
- the record after the 2 s transient cut into alternate 1 s blocks (the CSV's time column):
  even blocks fitted, odd ones held out; NMSE before (the physics run: a twin made by
  `twin calibrate` has no corrector), the noise level 100 σ²_f / var(y_f), the `none` gate;
  the scales of the candidates' priors from the physics run (storey drift RMS, floor velocity
  RMS, force RMS, the twin's k); the baseline log evidence of the twin as it is on the fitted
  blocks (noise variances at their MAP, Laplace);
- jobs: the recalibration (m, c, k under Table 1's priors, 8 starts, 1,500 simulations a start)
  and every candidate of the library (its own parameters and priors, `Candidate::parameters`,
  3 starts, 250 simulations a start), the physics held at the twin's values, `substeps` = 16
  while fitting (ours fits at 8, contacts stepped exactly: `integrator` = 2);
- one fit: z the parameters standardised by their priors; starts the prior mean then 3·N(0, 1)
  draws (numpy, seed 1: not ours' draws); per start up to 5 rounds of (least squares in z at
  fixed noise: residuals e^{−s_f/2}(y − ŷ) on the fitted samples plus z, scipy
  `least_squares(method="lm")` — MINPACK's LM; ours is LM on the normal equations — with the
  forward-difference Jacobian ours uses for effect parameters (for m, c, k ours takes the FMU's
  sensitivities), h = 1e-6·max(|z_j|, 1), ftol = xtol = 1e-9, at most 25·(p + 1) residual
  evaluations, the start's simulation budget enforced at each Jacobian as ours does) then a
  Newton update of each s_f, until every s_f moves < 1e-3; the best J wins; Laplace at it
  (central differences, h = 1e-4·max(|z_j|, 1)) → log evidence − baseline; the fit then scored
  at the twin's own substeps: NMSE after the transient and on the held-out blocks;
- the decision: the same gates (4× cut, 2× better than recalibration, recalibration within 3× of
  the noise), the passing candidate of highest evidence wins.

The jobs run in a process pool of as many workers as ours has threads (the CPUs this process may
use), each worker with its own FMU instance; each job is timed inside its worker, the whole
diagnosis (pool start-up included) in the main process. With --candidates the peer runs the
recalibration and only those candidates, and the full diagnosis is extrapolated: each candidate
not run costs ours' time × the median peer/ours ratio of the candidates of its kind that ran.

Ours: the JSON reports of `twin diagnose` runs (--ours: default threads, --ours-1: --threads 1),
made by scripts/bench-diagnose.sh; their "seconds" fields are the timings. Run through that
script.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import statistics
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
import zipfile
from collections import namedtuple
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import scipy
from fmpy import extract, read_model_description
from fmpy.fmi2 import (
    FMU2Slave,
    calloc,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
    fmi2Integer,
    fmi2Real,
    fmi2True,
    fmi2ValueReference,
    free,
)

import bench_records

ROOT = Path(__file__).resolve().parents[1]

# DiagnoseOptions::default(), Gates::default(), CalibrationSetup::default().
TRANSIENT = 2.0
BLOCK = 1.0
STARTS = 3
RECALIBRATION_STARTS = 8
SIMULATIONS_PER_START = 250
RECALIBRATION_SIMULATIONS_PER_START = 1500
FIT_SUBSTEPS = 16
SEED = 1
NONE_FACTOR = 2.0
REQUIRED_CUT = 4.0
BEAT_RECALIBRATION = 2.0
RECALIBRATION_NOISE_FACTOR = 3.0
NOISE_FRACTION = 0.02
NOISE_LOG_VARIANCE = 1.0
# The LM of calibrate/mod.rs: ftol = xtol = 1e-9, patience 25, gtol the crate's 30·ε.
LM_TOL = 1e-9
PATIENCE = 25
GTOL = 30 * np.finfo(float).eps
REFUSED_RESIDUAL = 1e6
PHYSICS = ["m1", "m2", "m3", "c1", "c2", "c3", "k1", "k2", "k3"]
RECORDED = ["acc1", "acc2", "acc3", "drift1", "drift2", "drift3", "vel1", "vel2", "vel3"]

Prior = namedtuple("Prior", "space mean variance")  # space "linear" | "log"


def table1_prior(name: str) -> Prior:
    return {"m": Prior("linear", 5.2, 0.5), "c": Prior("log", -4.605, 1.0), "k": Prior("linear", 4021.0, 10_000.0)}[name[0]]


# -- the effect library (diagnose/candidate.rs) ------------------------------------------------------
Candidate = namedtuple("Candidate", "kind at side")
SIDE_CODE = {"both": 0, "positive": 1, "negative": -1}


def library() -> list[Candidate]:
    out = [Candidate("contact", at, side) for at in (1, 2, 3) for side in ("both", "positive", "negative")]
    out += [Candidate(kind, at, "both") for kind in ("cubic", "friction") for at in (1, 2, 3)]
    return out


def label(c: Candidate) -> str:
    if c.kind == "contact":
        return f"contact@{c.at - 1}-{c.at}:{c.side}"
    return f"{c.kind}@{c.at}"


def prefix(c: Candidate) -> str:
    return f"contact{c.at - 1}{c.at}" if c.kind == "contact" else f"{c.kind}{c.at}"


def switches(c: Candidate) -> dict:
    out = {f"{prefix(c)}_enabled": True}
    if c.kind == "contact":
        out[f"{prefix(c)}_side"] = SIDE_CODE[c.side]
    return out


def candidate_parameters(c: Candidate, scales: dict) -> list[tuple[str, Prior]]:
    p, i = prefix(c), c.at - 1

    def positive(x):
        return x if x > 0 and math.isfinite(x) else 1.0

    if c.kind == "contact":
        return [(f"{p}_gap", Prior("log", math.log(0.7 * positive(scales["drift_rms"][i])), 1.0)),
                (f"{p}_stiffness", Prior("log", math.log(positive(scales["stiffness"][i])), 4.0))]
    if c.kind == "cubic":
        sd = positive(scales["stiffness"][i]) / positive(scales["drift_rms"][i]) ** 2
        return [(f"{p}_stiffness", Prior("linear", 0.0, sd * sd))]
    return [(f"{p}_force", Prior("log", math.log(0.05 * positive(scales["force_rms"])), 4.0)),
            (f"{p}_velocity_scale", Prior("log", math.log(0.1 * positive(scales["velocity_rms"][i])), 1.0))]


# -- the twin and the record -----------------------------------------------------------------------
def read_ssp(path: Path) -> tuple[dict, np.ndarray]:
    """The physics component's parameters (name → float/int/bool) and the noise variances."""
    ns = {"ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues"}

    def parameters(text: bytes) -> dict:
        out = {}
        for p in ET.fromstring(text).iterfind(".//ssv:Parameter", ns):
            for tag, cast in (("Real", float), ("Integer", int), ("Boolean", lambda v: v == "true")):
                node = p.find(f"ssv:{tag}", ns)
                if node is not None:
                    out[p.get("name")] = cast(node.get("value"))
        return out

    with zipfile.ZipFile(path) as z:
        physics = parameters(z.read("resources/physics.ssv"))
        twin = parameters(z.read("resources/twin.ssv"))
    missing = [n for n in PHYSICS if n not in physics] + [f"noise_variance{f}" for f in (1, 2, 3) if f"noise_variance{f}" not in twin]
    if missing:
        raise SystemExit(f"{path}: no value for {', '.join(missing)} (a twin made by `twin calibrate`?)")
    return physics, np.array([twin[f"noise_variance{f}"] for f in (1, 2, 3)])


class Record(bench_records.Record):
    def __init__(self, path: Path):
        super().__init__(path, TRANSIENT)
        self.slope = np.diff(self.force) / self.dt
        # blocks(): after the transient, even blocks of BLOCK s fitted, odd ones held out.
        block = np.floor((self.time[self.first:] - self.time[self.first]) / BLOCK).astype(int)
        after = np.arange(self.first, self.n)
        self.after = after
        self.fitted = after[block % 2 == 0]
        self.held_out = after[block % 2 == 1]


def nmse(y: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Per floor (rows), compare.rs's NMSE in %."""
    return 100.0 * ((y - p) ** 2).sum(axis=1) / (y.shape[1] * y.var(axis=1))


def rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.asarray(x) ** 2)))


# -- the FMU through fmpy ------------------------------------------------------------------------------
def _quiet_logger(*_args):
    pass


_CALLBACKS = fmi2CallbackFunctions()
_CALLBACKS.logger = fmi2CallbackLoggerTYPE(_quiet_logger)
_CALLBACKS.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
_CALLBACKS.freeMemory = fmi2CallbackFreeMemoryTYPE(free)


class Shear:
    """One FMU2Slave instance of the shear FMU, run again and again on one record."""

    def __init__(self, fmu: Path, unzip: str, record: Record, plain_api: bool = False):
        self.plain_api = plain_api
        self.md = read_model_description(str(fmu))
        self.unzip = unzip
        self.variables = {v.name: v for v in self.md.modelVariables}
        self.can_interpolate = bool(self.md.coSimulation.canInterpolateInputs)
        self.record = record
        self.simulations = 0
        self.slave = self._instance()

    def _instance(self) -> FMU2Slave:
        slave = FMU2Slave(guid=self.md.guid, unzipDirectory=self.unzip,
                          modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName="peer")
        slave.instantiate(callbacks=_CALLBACKS)
        return slave

    def vr(self, name: str) -> int:
        return self.variables[name].valueReference

    def close(self) -> None:
        try:
            self.slave.terminate()
            self.slave.freeInstance()
        except Exception:
            pass

    def run(self, parameters: dict, outputs: list[str]) -> np.ndarray | None:
        """outputs × samples, or None when the FMU refuses the parameters or diverges."""
        self.simulations += 1
        rec, slave = self.record, self.slave
        try:
            slave.reset()
            slave.setupExperiment(startTime=float(rec.time[0]))
            slave.enterInitializationMode()
            for name, value in parameters.items():
                v = self.variables[name]
                if v.type == "Real":
                    slave.setReal([v.valueReference], [float(value)])
                elif v.type == "Integer":
                    slave.setInteger([v.valueReference], [int(value)])
                else:
                    slave.setBoolean([v.valueReference], [bool(value)])
            slave.exitInitializationMode()
            n, dt, t0 = rec.n, rec.dt, float(rec.time[0])
            force, slope = rec.force.tolist(), rec.slope.tolist()
            interpolate = self.can_interpolate
            if self.plain_api:
                # FMU2Slave's convenience methods: new ctypes arrays at every call.
                force_vr = [self.vr("force")]
                out_vrs = [self.vr(o) for o in outputs]
                rows = [None] * n
                for k in range(n):
                    slave.setReal(force_vr, [force[k]])
                    rows[k] = slave.getReal(out_vrs)
                    if k + 1 < n:
                        if interpolate:
                            slave.setRealInputDerivatives(force_vr, [1], [slope[k]])
                        slave.doStep(t0 + k * dt, dt)
                out = np.array(rows).T
            else:
                # The same calls through FMU2Slave's fmi2* attributes (fmpy's status-checked
                # wrappers of the C functions) with ctypes buffers made once per run.
                c = slave.component
                m = len(outputs)
                force_vr = (fmi2ValueReference * 1)(self.vr("force"))
                out_vrs = (fmi2ValueReference * m)(*[self.vr(o) for o in outputs])
                order, value, derivative, read = (fmi2Integer * 1)(1), (fmi2Real * 1)(), (fmi2Real * 1)(), (fmi2Real * m)()
                set_real, get_real = slave.fmi2SetReal, slave.fmi2GetReal
                set_derivative, do_step = slave.fmi2SetRealInputDerivatives, slave.fmi2DoStep
                out = np.empty((n, m))
                for k in range(n):
                    value[0] = force[k]
                    set_real(c, force_vr, 1, value)
                    get_real(c, out_vrs, m, read)
                    out[k] = read
                    if k + 1 < n:
                        if interpolate:
                            derivative[0] = slope[k]
                            set_derivative(c, force_vr, 1, order, derivative)
                        do_step(c, t0 + k * dt, dt, fmi2True)
                out = out.T
        except Exception:
            try:
                slave.reset()
            except Exception:  # a fresh instance when the old one cannot recover
                self.slave = self._instance()
            return None
        return out if np.all(np.isfinite(out)) else None


# -- MAP fit with Laplace evidence (calibrate/mod.rs) ---------------------------------------------
class Budget(Exception):
    """A start used up its simulations (or the FMU refused the point): LM stops at x."""

    def __init__(self, x):
        self.x = x


def optimal_log_noise(n, sse, mean, var, start):
    s = start
    for _ in range(50):
        g = n / 2 - sse * math.exp(-s) / 2 + (s - mean) / var
        h = sse * math.exp(-s) / 2 + 1 / var
        step = g / h
        s -= min(max(step, -5.0), 5.0)
        if abs(step) < 1e-12:
            break
    return s


class Target:
    """Parameters `names` (priors `priors`) of the FMU with `base` fixed, on the fitted samples."""

    def __init__(self, shear: Shear, base: dict, names: list[str], priors: list[Prior], used: np.ndarray, budget: int):
        self.shear, self.base, self.names, self.priors, self.used, self.budget = shear, base, names, priors, used, budget
        self.mean = np.array([p.mean for p in priors])
        self.sd = np.sqrt([p.variance for p in priors])
        self.log = np.array([p.space == "log" for p in priors])
        y = shear.record.acc[:, used]
        self.measured = y
        self.noise_mean = np.log(NOISE_FRACTION * y.var(axis=1))

    def values(self, z):
        u = self.mean + self.sd * np.asarray(z)
        return np.where(self.log, np.exp(np.where(self.log, u, 0.0)), u)

    def residuals(self, z) -> np.ndarray | None:
        """y − ŷ on the fitted samples, 3 × N, or None if refused."""
        with np.errstate(over="ignore", invalid="ignore"):
            values = self.values(z)
        if not np.all(np.isfinite(values)):
            return None
        params = dict(self.base)
        params.update({n: float(v) for n, v in zip(self.names, values)})
        acc = self.shear.run(params, ["acc1", "acc2", "acc3"])
        return None if acc is None else self.measured - acc[:, self.used]

    def objective(self, sse, s, z) -> float:
        n = self.measured.shape[1]
        data = n * s / 2 + sse * np.exp(-s) / 2 + (s - self.noise_mean) ** 2 / (2 * NOISE_LOG_VARIANCE)
        return float(data.sum() + 0.5 * np.dot(z, z))


def lm(target: Target, z0: np.ndarray, s: np.ndarray, budget: int) -> tuple[np.ndarray, int]:
    """least_squares on the weighted residuals plus z, ours' forward-difference Jacobian."""
    from scipy.optimize import least_squares

    w = np.exp(-s / 2)
    p = len(z0)
    m = 3 * target.measured.shape[1] + p
    used = [0]
    cache = {}

    def fun(z):
        key = z.tobytes()
        if key not in cache:
            used[0] += 1
            r = target.residuals(z)
            cache.clear()
            cache[key] = (np.full(m, REFUSED_RESIDUAL) if r is None else np.concatenate([(r * w[:, None]).ravel(), z]), r is None)
        return cache[key][0]

    def jac(z):
        if used[0] > budget:
            raise Budget(z.copy())
        base = fun(z)
        if cache[z.tobytes()][1]:
            raise Budget(z.copy())
        j = np.empty((m, p))
        for i in range(p):
            h = 1e-6 * max(abs(z[i]), 1.0)
            zi = z.copy()
            zi[i] += h
            used[0] += 1
            r = target.residuals(zi)
            if r is None:
                raise Budget(z.copy())
            j[:, i] = (np.concatenate([(r * w[:, None]).ravel(), zi]) - base) / h
        return j

    try:
        result = least_squares(fun, z0, jac=jac, method="lm", ftol=LM_TOL, xtol=LM_TOL, gtol=GTOL,
                               x_scale="jac", max_nfev=PATIENCE * (p + 1))
        z = result.x
    except Budget as stop:
        z = stop.x
    return z, used[0]


def run_start(target: Target, z0: np.ndarray) -> dict | None:
    n = target.measured.shape[1]
    s, z, evaluations = target.noise_mean.copy(), z0, 0
    for _ in range(5):
        z, used = lm(target, z, s, max(target.budget - evaluations, 0))
        evaluations += used
        r = target.residuals(z)
        evaluations += 1
        if r is None:
            return None
        sse = (r ** 2).sum(axis=1)
        s_new = np.array([optimal_log_noise(n, sse[f], target.noise_mean[f], NOISE_LOG_VARIANCE, s[f]) for f in range(3)])
        settled = np.all(np.abs(s_new - s) < 1e-3)
        s = s_new
        if settled:
            break
    r = target.residuals(z)
    if r is None:
        return None
    j = target.objective((r ** 2).sum(axis=1), s, z)
    return {"z": z, "s": s, "objective": j, "evaluations": evaluations + 1} if math.isfinite(j) else None


def laplace_log_det(target: Target, z: np.ndarray, s: np.ndarray) -> float:
    """½ log det of the posterior covariance of (z, s) at the optimum (−inf if not SPD)."""
    p, n = len(z), target.measured.shape[1]
    r0 = target.residuals(z)
    if r0 is None:
        return -math.inf
    jac = np.empty((3, n, p))
    for j in range(p):
        h = 1e-4 * max(abs(z[j]), 1.0)
        zp, zm = z.copy(), z.copy()
        zp[j] += h
        zm[j] -= h
        rp, rm = target.residuals(zp), target.residuals(zm)
        if rp is None or rm is None:
            return -math.inf
        jac[:, :, j] = (rp - rm) / (2 * h)
    hess = np.zeros((p + 3, p + 3))
    for f in range(3):
        w = math.exp(-s[f])
        hess[:p, :p] += w * jac[f].T @ jac[f]
        cross = -w * jac[f].T @ r0[f]
        hess[:p, p + f] = cross
        hess[p + f, :p] = cross
        hess[p + f, p + f] = (r0[f] ** 2).sum() * w / 2 + 1 / NOISE_LOG_VARIANCE
    hess[:p, :p] += np.eye(p)
    try:
        cov = np.linalg.inv(hess)
        chol = np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        return -math.inf
    return float(np.log(np.diag(chol)).sum())  # ½ · 2 Σ log diag L


def calibrate(target: Target, starts: int) -> dict:
    rng = np.random.default_rng(SEED)
    p = len(target.names)
    zs = [np.zeros(p) if i == 0 else 3.0 * rng.standard_normal(p) for i in range(starts)]
    before = target.shear.simulations
    results = [r for r in (run_start(target, z0) for z0 in zs) if r is not None]
    if not results:
        raise RuntimeError("no start converged to a finite posterior")
    best = min(results, key=lambda r: r["objective"])
    half_log_det = laplace_log_det(target, best["z"], best["s"])
    target.residuals(best["z"])  # calibrate()'s own NMSE run at the fit's substeps
    return {"values": target.values(best["z"]), "z": best["z"], "s": best["s"], "objective": best["objective"],
            "log_evidence": -best["objective"] + half_log_det,
            "simulations": target.shear.simulations - before,
            "starts": [r["objective"] for r in results]}


def fixed_log_evidence(acc: np.ndarray, record: Record) -> float:
    """The twin as it is on the fitted samples: noise at its MAP, integrated out by Laplace."""
    y = record.acc[:, record.fitted]
    n = y.shape[1]
    total = 0.0
    for f in range(3):
        mean = math.log(NOISE_FRACTION * y[f].var())
        sse = float(((y[f] - acc[f, record.fitted]) ** 2).sum())
        s = optimal_log_noise(n, sse, mean, NOISE_LOG_VARIANCE, mean)
        j = n * s / 2 + sse * math.exp(-s) / 2 + (s - mean) ** 2 / (2 * NOISE_LOG_VARIANCE)
        total += -j - 0.5 * math.log(sse * math.exp(-s) / 2 + 1 / NOISE_LOG_VARIANCE)
    return total


# -- the jobs, in worker processes --------------------------------------------------------------------
_ctx: dict = {}


def _init_worker(fmu: str, unzip: str, data: str, physics: dict, scales: dict, baseline: float, plain_api: bool) -> None:
    record = Record(Path(data))
    _ctx.update(shear=Shear(Path(fmu), unzip, record, plain_api), record=record, physics=physics, scales=scales, baseline=baseline)


def _run_job(job: str) -> dict:
    started = time.perf_counter()
    shear, record, physics = _ctx["shear"], _ctx["record"], _ctx["physics"]
    if job == "recalibration":
        names, priors = PHYSICS, [table1_prior(n) for n in PHYSICS]
        starts, budget = RECALIBRATION_STARTS, RECALIBRATION_SIMULATIONS_PER_START
        base = {k: v for k, v in physics.items() if k not in PHYSICS}
    else:
        c = next(c for c in library() if label(c) == job)
        spec = candidate_parameters(c, _ctx["scales"])
        names, priors = [s[0] for s in spec], [s[1] for s in spec]
        base = {**physics, **switches(c)}
        starts, budget = STARTS, SIMULATIONS_PER_START
    coarse = {**base, "substeps": FIT_SUBSTEPS}
    fit = calibrate(Target(shear, coarse, names, priors, record.fitted, budget), starts)
    # Scored at the twin's own substeps.
    run = shear.run({**base, **dict(zip(names, map(float, fit["values"])))}, ["acc1", "acc2", "acc3"])
    if run is None:
        raise RuntimeError(f"{job}: the fitted parameters do not run at the twin's substeps")
    return {"job": job, "names": names, "values": fit["values"].tolist(), "noise_variance": np.exp(fit["s"]).tolist(),
            "evidence": fit["log_evidence"] - _ctx["baseline"],
            "nmse_after": nmse(record.acc[:, record.after], run[:, record.after]).tolist(),
            "nmse_held_out": nmse(record.acc[:, record.held_out], run[:, record.held_out]).tolist(),
            "simulations": fit["simulations"] + 1, "seconds": time.perf_counter() - started}


def cpu_seconds() -> float:
    """User + system time of this process and its waited-for children (the pool's workers)."""
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + children.ru_utime + children.ru_stime


def peer_diagnosis(fmu: Path, data: Path, ssp: Path, candidates: list[str], workers: int, plain_api: bool) -> dict:
    cpu = cpu_seconds()
    with tempfile.TemporaryDirectory(prefix="bench-diagnose-") as unzip:
        out = _peer_diagnosis(fmu, unzip, data, ssp, candidates, workers, plain_api)
    out["cpu_seconds"] = cpu_seconds() - cpu
    return out


def _peer_diagnosis(fmu: Path, unzip: str, data: Path, ssp: Path, candidates: list[str], workers: int,
                    plain_api: bool) -> dict:
    started = time.perf_counter()
    physics, noise_variance = read_ssp(ssp)
    record = Record(data)
    extract(str(fmu), unzipdir=unzip)
    shear = Shear(fmu, unzip, record, plain_api)
    try:
        base = shear.run(physics, RECORDED)
    finally:
        shear.close()
    if base is None:
        raise SystemExit("the calibrated twin does not run through fmpy")
    acc, drift, vel = base[0:3], base[3:6], base[6:9]
    y = record.acc
    nmse_before = nmse(y[:, record.after], acc[:, record.after])
    before_held = nmse(y[:, record.held_out], acc[:, record.held_out])
    noise_nmse = 100 * noise_variance / y[:, record.after].var(axis=1)
    noise_held = 100 * noise_variance / y[:, record.held_out].var(axis=1)
    out = {"nmse_before": nmse_before.tolist(), "noise_nmse": noise_nmse.tolist(), "jobs": {}}
    if np.all(nmse_before / noise_nmse <= NONE_FACTOR):
        out.update(action="none", effect=None, nmse_after=nmse_before.tolist(), seconds=time.perf_counter() - started)
        return out
    f = record.first
    scales = {"stiffness": [physics[f"k{i}"] for i in (1, 2, 3)],
              "drift_rms": [rms(drift[i, f:]) for i in range(3)],
              "velocity_rms": [rms(vel[i, f:]) for i in range(3)],
              "force_rms": rms(record.force[f:])}
    baseline = fixed_log_evidence(acc, record)
    jobs = ["recalibration"] + candidates
    with ProcessPoolExecutor(max_workers=workers, initializer=_init_worker,
                             initargs=(str(fmu), unzip, str(data), physics, scales, baseline, plain_api)) as pool:
        results = list(pool.map(_run_job, jobs, chunksize=1))
    recal = results[0]
    before_worst, recal_worst = max(before_held), max(recal["nmse_held_out"])
    for r in results[1:]:
        w = max(r["nmse_held_out"])
        r["passes"] = w * REQUIRED_CUT <= before_worst and w * BEAT_RECALIBRATION <= recal_worst
    ranked = sorted(results[1:], key=lambda r: -r["evidence"])
    winner = next((r for r in ranked if r["passes"]), None)
    recal_explains = recal_worst * REQUIRED_CUT <= before_worst and all(
        recal["nmse_held_out"][i] <= RECALIBRATION_NOISE_FACTOR * noise_held[i] for i in range(3))
    if winner:
        out.update(action="add_physics", effect=winner["job"], nmse_after=winner["nmse_after"])
    elif recal_explains:
        out.update(action="recalibrate", effect=None, nmse_after=recal["nmse_after"])
    else:
        out.update(action="update_data_model", effect=None, nmse_after=nmse_before.tolist())
    out["seconds"] = time.perf_counter() - started
    out["jobs"] = {r["job"]: r for r in results}
    return out


# -- ours, from its reports, and the comparison -----------------------------------------------------
def ours_jobs(report: dict) -> dict:
    recal = report["recalibration"]
    after = {q["name"]: q["after"] for q in recal["parameters"]}
    jobs = {"recalibration": {"seconds": recal["seconds"], "simulations": recal["simulations"],
                              "evidence": recal["evidence"], "nmse_held_out": recal["nmse_held_out"],
                              "values": [after[n] for n in PHYSICS]}}
    for c in report["candidates"]:
        jobs[c["label"]] = {k: c[k] for k in ("seconds", "simulations", "evidence", "nmse_held_out", "passes")}
        jobs[c["label"]]["values"] = [q["value"] for q in c["parameters"]]  # in Candidate::parameters' order
    return jobs


def decide(report: dict, candidates: list[str]) -> tuple[str, str | None]:
    """Ours' decision (diagnose step 5) from its report, among `candidates` only."""
    if report["recalibration"] is None:
        return report["action"], None
    before_worst = max(report["nmse_before_held_out"])
    recal = report["recalibration"]["nmse_held_out"]
    passing = [c for c in report["candidates"] if c["label"] in candidates and c["passes"]]
    if passing:
        return "add_physics", max(passing, key=lambda c: c["evidence"])["label"]
    if max(recal) * REQUIRED_CUT <= before_worst and all(
            recal[i] <= RECALIBRATION_NOISE_FACTOR * report["noise_nmse_held_out"][i] for i in range(3)):
        return "recalibrate", None
    return "update_data_model", None


def median(xs):
    return statistics.median(xs)


def times(reports) -> str:
    return ", ".join(f"{r['seconds']:.2f}" for r in reports)


def pct(x) -> str:
    return " / ".join(f"{v:.3f}" for v in x)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--ssp", type=Path, required=True, help="the calibrated twin")
    parser.add_argument("--data", type=Path, default=ROOT / "data" / "dataset3.csv")
    parser.add_argument("--fmu", type=Path, default=ROOT / "target" / "fmu" / "fmu_shear.fmu")
    parser.add_argument("--ours", type=Path, nargs="+", required=True, help="reports of `twin diagnose` (default threads)")
    parser.add_argument("--ours-1", type=Path, nargs="+", required=True, help="reports of `twin diagnose --threads 1`")
    parser.add_argument("--ours-cpu", type=Path, nargs="*", default=[],
                        help="per run of --ours, a file 'wall user system' (seconds) of the process")
    parser.add_argument("--threads", type=int, default=0, help="ours' default threads (0: the CPUs this process may use)")
    parser.add_argument("--peer-runs", type=int, default=1)
    parser.add_argument("--peer-workers", type=int, default=0, help="0: as many as ours' threads")
    parser.add_argument("--candidates", nargs="*", help="the peer runs only these (labels); default: the whole library")
    parser.add_argument("--plain-api", action="store_true",
                        help="the peer's step loop through FMU2Slave's convenience methods (about 2× slower)")
    parser.add_argument("--json", type=Path, help="also write the figures to this file")
    args = parser.parse_args()

    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    threads = args.threads or cpus
    workers = args.peer_workers or threads
    all_labels = [label(c) for c in library()]
    chosen = all_labels if args.candidates is None else args.candidates
    unknown = [c for c in chosen if c not in all_labels]
    if unknown:
        raise SystemExit(f"unknown candidates {unknown}; the library: {' '.join(all_labels)}")
    ours = [json.loads(p.read_text()) for p in args.ours]
    ours1 = [json.loads(p.read_text()) for p in args.ours_1]

    peers = []
    for i in range(args.peer_runs):
        peer = peer_diagnosis(args.fmu, args.data, args.ssp, chosen, workers, args.plain_api)
        print(f"peer run {i + 1}/{args.peer_runs}: {peer['seconds']:.1f} s, {peer['action']} {peer['effect'] or ''}",
              file=sys.stderr, flush=True)
        peers.append(peer)

    if ours[-1]["recalibration"] is None or not peers[-1]["jobs"]:
        print(f"nothing fitted: ours {ours[-1]['action']} in {median([r['seconds'] for r in ours]):.2f} s, "
              f"peer {peers[-1]['action']} in {median([q['seconds'] for q in peers]):.2f} s (the error is within the noise)")
        return
    t_ours, t_ours1 = median([r["seconds"] for r in ours]), median([r["seconds"] for r in ours1])
    t_peer = median([p["seconds"] for p in peers])
    o, p = ours[-1], peers[-1]
    oj = [ours_jobs(r) for r in ours]
    oj1 = [ours_jobs(r) for r in ours1]
    labels = ["recalibration"] + all_labels
    ran = ["recalibration"] + chosen
    rows = {}
    for name in labels:
        row = {"ours_s": median([j[name]["seconds"] for j in oj]), "ours_1_s": median([j[name]["seconds"] for j in oj1]),
               "ours_sims": oj[-1][name]["simulations"], "ours_evidence": oj[-1][name]["evidence"],
               "ours_held_out_worst": max(oj[-1][name]["nmse_held_out"])}
        if name in ran:
            row.update(peer_s=median([q["jobs"][name]["seconds"] for q in peers]),
                       peer_sims=p["jobs"][name]["simulations"], peer_evidence=p["jobs"][name]["evidence"],
                       peer_held_out_worst=max(p["jobs"][name]["nmse_held_out"]))
            row["ratio"] = row["peer_s"] / row["ours_s"]
        rows[name] = row

    # Extrapolation to the whole library: candidates not run cost ours' time × the median ratio
    # of those of their kind that ran (of all that ran, if none of the kind did).
    def kind(name):
        return name.split("@")[0]

    ratios = [rows[n]["ratio"] for n in chosen]
    for name in all_labels:
        if name not in chosen:
            same = [rows[n]["ratio"] for n in chosen if kind(n) == kind(name)] or ratios
            rows[name]["peer_s_estimate"] = rows[name]["ours_s"] * median(same) if same else math.nan
    job_sum_ours = sum(rows[n]["ours_s"] for n in labels)
    job_sum_peer = sum(rows[n].get("peer_s", rows[n].get("peer_s_estimate", math.nan)) for n in labels)
    complete = set(chosen) == set(all_labels)

    print()
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    print(f"twin diagnose of {args.data.name} (twin calibrated on dataset1), same machine, same run; {cpus} CPUs, "
          f"load average now {load} (other work on the machine slows both sides)")
    print(f"ours: twin diagnose, median of {len(ours)} runs each; peer: fmpy {__import__('fmpy').__version__} FMU2Slave "
          f"({'convenience methods' if args.plain_api else 'fmi2* calls, buffers made once'}) "
          f"+ scipy {scipy.__version__} least_squares(method='lm'), {workers} worker processes, "
          f"{'full library' if complete else f'recalibration + {len(chosen)} of {len(all_labels)} candidates'}, "
          f"median of {len(peers)} run(s)")
    print(f"  ours, {threads} threads (default):  {t_ours:7.2f} s   runs {times(ours)}")
    print(f"  ours, --threads 1:           {t_ours1:7.2f} s   runs {times(ours1)}")
    cpu = [sum(map(float, f.read_text().split()[1:3])) / float(f.read_text().split()[0]) for f in args.ours_cpu]
    if cpu:
        print(f"  cores ours' {threads}-thread runs got (CPU time / wall, process): {', '.join(f'{c:.2f}' for c in cpu)}; "
              f"the peer's: {', '.join(format(q['cpu_seconds'] / q['seconds'], '.2f') for q in peers)}")
    print(f"  parallel speed-up (1 thread / {threads}):  {t_ours1 / t_ours:.2f}×   (goal: a diagnosis under 30 s: "
          f"{'met' if t_ours < 30 else 'NOT met'})")
    print(f"  ours: action {o['action']}, effect {(o.get('effect') or {}).get('label', '-')}, NMSE after {pct(o['nmse_after'])} %")
    print(f"  peer: action {p['action']}, effect {p['effect'] or '-'}, NMSE after {pct(p['nmse_after'])} %")
    if complete:
        print(f"  peer, {workers} workers:             {t_peer:7.2f} s   runs {times(peers)}")
        print(f"  ratio peer / ours (wall, both {threads}-way parallel): {t_peer / t_ours:.1f}")
    else:
        print(f"  peer, {workers} workers, the subset: {t_peer:7.2f} s   runs {times(peers)}")
    print(f"  sum of job times: ours {job_sum_ours:.1f} s, peer {job_sum_peer:.1f} s"
          f"{'' if complete else ' (extrapolated)'}: ratio peer / ours {job_sum_peer / job_sum_ours:.1f}")
    print()
    print(f"  {'job':22s} {'ours s':>7s} {'ours 1t':>7s} {'peer s':>7s} {'ratio':>6s} {'sims o/p':>11s}"
          f" {'held-out worst % o/p':>21s} {'evidence o/p':>17s}")
    for name in labels:
        r = rows[name]
        if "peer_s" in r:
            print(f"  {name:22s} {r['ours_s']:7.2f} {r['ours_1_s']:7.2f} {r['peer_s']:7.2f} {r['ratio']:6.1f}"
                  f" {r['ours_sims']:>5d}/{r['peer_sims']:<5d} {r['ours_held_out_worst']:>10.3f}/{r['peer_held_out_worst']:<10.3f}"
                  f" {r['ours_evidence']:>8.1f}/{r['peer_evidence']:<8.1f}")
        else:
            print(f"  {name:22s} {r['ours_s']:7.2f} {r['ours_1_s']:7.2f} {'~' + format(r['peer_s_estimate'], '.1f'):>7s}"
                  f" {'(est)':>6s} {r['ours_sims']:>5d}/{'-':<5s} {r['ours_held_out_worst']:>10.3f}/{'-':<10s}"
                  f" {r['ours_evidence']:>8.1f}/{'-':<8s}")
    # Sanity check: the same decision, and how close the fits are.
    both = [n for n in ran if n in rows and "peer_s" in rows[n]]
    rel = [abs(rows[n]["peer_held_out_worst"] - rows[n]["ours_held_out_worst"]) / rows[n]["ours_held_out_worst"] for n in both]
    close = sum(1 for x in rel if x <= 0.05)
    ours_action, ours_winner = decide(o, chosen)
    peer_pass = sorted(n for n in chosen if p["jobs"][n]["passes"])
    ours_pass = sorted(n for n in chosen if oj[-1][n]["passes"])
    print()
    same = ours_action == p["action"] and ours_winner == p["effect"]
    print(f"  same decision: {'yes' if same else 'NO'} (ours {ours_action} {ours_winner or ''}, peer {p['action']} "
          f"{p['effect'] or ''}){'' if complete else ' — ours decided again among the candidates the peer ran'}")
    print(f"  passing the gates: ours {', '.join(ours_pass) or '-'}; peer {', '.join(peer_pass) or '-'}")
    # The same optimum: evidence within 0.5 (a log Bayes factor, so well below anything the
    # ranking looks at). For those, how close the numbers are; the others are listed.
    same_optimum = [n for n in both if abs(p["jobs"][n]["evidence"] - oj[-1][n]["evidence"]) < 0.5]
    other = [n for n in both if n not in same_optimum]
    if same_optimum:
        rel_same = [rel[both.index(n)] for n in same_optimum]
        value_gap = [float(np.max(np.abs(np.array(p["jobs"][n]["values"]) - oj[-1][n]["values"])
                                  / np.abs(oj[-1][n]["values"]))) for n in same_optimum]
        evidence_gap = [abs(p["jobs"][n]["evidence"] - oj[-1][n]["evidence"]) for n in same_optimum]
        print(f"  same optimum (evidence within 0.5) in {len(same_optimum)}/{len(both)} jobs; in those, peer vs ours: "
              f"worst-floor held-out NMSE relative difference ≤ {max(rel_same):.1e},")
        print(f"    fitted parameters relative difference ≤ {max(value_gap):.1e} (median {median(value_gap):.1e}), "
              f"evidence difference ≤ {max(evidence_gap):.1e}")
    for n in other:
        oe, pe = oj[-1][n]["evidence"], p["jobs"][n]["evidence"]
        print(f"  different optimum: {n}: evidence ours {oe:.1f}, peer {pe:.1f} ({'ours' if oe > pe else 'the peer'} found "
              f"the better one); worst-floor held-out NMSE ours {rows[n]['ours_held_out_worst']:.3f} %, "
              f"peer {rows[n]['peer_held_out_worst']:.3f} %")
    print(f"  all {len(both)} jobs: worst-floor held-out NMSE within 5 % of ours in {close}")
    print("  (scipy's 'lm' is MINPACK's LM, ours LM on the normal equations with the FMU's sensitivities for m, c, k;")
    print("   the start draws differ (numpy vs Rust RNG) and so can the local optimum a multi-start fit ends in)")
    # What a simulation costs each side (job seconds / simulations): the peer drives 1024 steps
    # through ctypes from Python; ours runs in-process, and without an effect the FMU's linear
    # step map makes a recalibration simulation far cheaper than a candidate's.
    def per_sim(side, names):
        key_s, key_n = (f"{side}_s", f"{side}_sims")
        return 1000 * median([rows[n][key_s] / rows[n][key_n] for n in names])

    cands = [n for n in chosen]
    print(f"  ms per simulation (job time / simulations, median): recalibration ours {per_sim('ours', ['recalibration']):.2f}, "
          f"peer {per_sim('peer', ['recalibration']):.2f}; candidates ours {per_sim('ours', cands):.2f}, "
          f"peer {per_sim('peer', cands):.2f}")
    if args.json:
        args.json.write_text(json.dumps({"ours_s": t_ours, "ours_1_s": t_ours1, "peer_s": t_peer, "complete": complete,
                                         "rows": rows, "ours_action": o["action"], "peer": peers}, indent=2,
                                        default=float) + "\n")


if __name__ == "__main__":
    sys.exit(main())
