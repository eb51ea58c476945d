#!/usr/bin/env python3
"""Peer of `twin learn --mode fixed`: Algorithm 1 of the reference paper (stream-based active
learning, fixed threshold) in numpy/scipy, on the same inputs as ours.

Inputs: the physics predictions of the calibrated twin on each record, as written by
`twin compare --predictions` (time,acc1,acc2,acc3), and the records themselves. From them the
same GP inputs (lags of the three physics accelerations and the force, channel by channel,
oldest first, the missing lags padded with the first sample), the same discrepancy targets
(measured - physics), the same transient cut-off (2 s), the same initial set (first 75 points
after it), the same default fixed threshold (1e-3 x each floor's measured variance on the first
record, after the transient) and the same NMSE after each query (means over the whole record).

The GP fits as ours do (numerics::gp::fit): NLML/N and its gradient in log-hyperparameters,
L-BFGS-B in the same data-based box (log l_d in [log(1e-3 sd_d), log(1e3 sd_d sqrt(d))],
sigma_f^2 in [1e-6 v, 1e3 v], sigma_n^2 in [1e-8 v, 10 v], v the targets' variance), the same
stopping tests (projected gradient 1e-5, relative reduction 1e-9); the initial fit takes the
best of three starts (the data-based one and two N(0, 1) perturbations of it in every log
coordinate; ours draws them from its own seeded generator, so the perturbed starts differ);
refits follow the same schedule (`twin learn`'s defaults: at least 25 queries and a third of
the training set at the last fit since it, warm-started, at most 100 iterations up to 512 points,
100 (512/n)^3 but at least 10 beyond).

Differences, on purpose (it is the straightforward implementation): each query refactors
K (O(n^3)) instead of appending a row to the Cholesky factor (O(n^2)); every point's latent
variance is a fresh triangular solve. Timed: the learning loop only (not reading the files).

    bench_learn.py --data D1.csv D2.csv D3.csv --predictions P1.csv P2.csv P3.csv [--lags 9]
                   [--refit-every 25] [--refit-growth 0.3333] [--refit-iterations 100]
                   [--json out.json]
"""
import argparse
import json
import time

import numpy as np
from scipy.linalg import cho_factor, cho_solve, solve_triangular
from scipy.optimize import minimize

SQRT3 = np.sqrt(3.0)


def read_csv(path):
    with open(path) as f:
        header = f.readline().strip().split(",")
    data = np.loadtxt(path, delimiter=",", skiprows=1)
    return {name: data[:, i] for i, name in enumerate(header)}


def lagged_inputs(samples, lags):
    # samples: N x 4 (phys1, phys2, phys3, force); row k: per channel [s(k-q) .. s(k)].
    n = samples.shape[0]
    rows = np.empty((n, 4 * (lags + 1)))
    for k in range(n):
        idx = [max(k - lags + j, 0) for j in range(lags + 1)]
        # before q samples have been seen, the missing ones are the first sample
        rows[k] = samples[idx].T.reshape(-1)
    return rows


def kernel(a, b, ls, sf2):
    d = (a[:, None, :] - b[None, :, :]) / ls
    r = np.sqrt(np.maximum((d * d).sum(-1), 0.0))
    return sf2 * (1 + SQRT3 * r) * np.exp(-SQRT3 * r)


def nlml_grad(theta, x, y):
    dim = x.shape[1]
    ls = np.exp(theta[:dim])
    sf2, sn2 = np.exp(theta[dim]), np.exp(theta[dim + 1])
    n = len(y)
    diff2 = ((x[:, None, :] - x[None, :, :]) / ls) ** 2
    r = np.sqrt(np.maximum(diff2.sum(-1), 0.0))
    e = np.exp(-SQRT3 * r)
    kf = sf2 * (1 + SQRT3 * r) * e
    k = kf + sn2 * np.eye(n)
    try:
        c = cho_factor(k, lower=True)
    except np.linalg.LinAlgError:
        return 1e10, np.zeros_like(theta)
    alpha = cho_solve(c, y)
    nll = 0.5 * y @ alpha + np.log(np.diag(c[0])).sum() + 0.5 * n * np.log(2 * np.pi)
    w = cho_solve(c, np.eye(n)) - np.outer(alpha, alpha)
    g = np.empty_like(theta)
    base = 3 * sf2 * e
    for d in range(dim):
        g[d] = 0.5 * np.sum(w * base * diff2[:, :, d])
    g[dim] = 0.5 * np.sum(w * kf)
    g[dim + 1] = 0.5 * sn2 * np.trace(w)
    return nll / n, g / n


def target_scale(y):
    v = y.var()
    if v > 0 and np.isfinite(v):
        return v
    m2 = y.mean() ** 2
    return m2 if m2 > 0 and np.isfinite(m2) else 1.0


def feature_scales(x):
    sd = x.std(0)
    return np.where((sd > 0) & np.isfinite(sd), sd, 1.0)


def box(x, y, noise_floor=1e-8):
    """numerics::gp::Bounds::from_data."""
    sd, v, dim = feature_scales(x), target_scale(y), x.shape[1]
    lower = np.concatenate([np.log(1e-3 * sd), [np.log(1e-6 * v), np.log(noise_floor * v)]])
    upper = np.concatenate([np.log(1e3 * sd * np.sqrt(dim)), [np.log(1e3 * v), np.log(10 * v)]])
    return lower, upper


def data_start(x, y):
    dim = x.shape[1]
    v = target_scale(y)
    return np.concatenate([np.log(feature_scales(x) * np.sqrt(dim)), [np.log(v), np.log(1e-2 * v)]])


def fit(x, y, starts, maxiter):
    """Best of L-BFGS-B runs from `starts` (clamped into the box)."""
    lower, upper = box(x, y)
    best = None
    for theta0 in starts:
        theta0 = np.clip(theta0, lower, upper)
        res = minimize(nlml_grad, theta0, args=(x, y), jac=True, method="L-BFGS-B",
                       bounds=list(zip(lower, upper)),
                       options={"maxiter": maxiter, "gtol": 1e-5, "ftol": 1e-9})
        if best is None or res.fun < best.fun:
            best = res
    return best.x


def initial_starts(x, y, rng):
    base = data_start(x, y)
    return [base] + [base + rng.standard_normal(base.shape) for _ in range(2)]


class Gp:
    def __init__(self, x, y, theta):
        self.x, self.y, self.theta = x, y, theta
        self.factor()

    def factor(self):
        dim = self.x.shape[1]
        self.ls = np.exp(self.theta[:dim])
        self.sf2, self.sn2 = np.exp(self.theta[dim]), np.exp(self.theta[dim + 1])
        k = kernel(self.x, self.x, self.ls, self.sf2) + self.sn2 * np.eye(len(self.y))
        self.l = np.linalg.cholesky(k)
        self.alpha = cho_solve((self.l, True), self.y)

    def latent(self, xs):
        ks = kernel(self.x, xs, self.ls, self.sf2)
        v = solve_triangular(self.l, ks, lower=True)
        return np.maximum(self.sf2 - (v * v).sum(0), 0.0)

    def mean(self, xs):
        return kernel(xs, self.x, self.ls, self.sf2) @ self.alpha


def describe(gps, record, query, end_of_record):
    """A refit as `twin learn` reports it: NLML (not divided by N), sigma_f^2, sigma_n^2."""
    dim = gps[0].x.shape[1]
    return {"record": record, "query": query, "end_of_record": end_of_record,
            "training_points": len(gps[0].y),
            "nlml_after": [len(gp.y) * nlml_grad(gp.theta, gp.x, gp.y)[0] for gp in gps],
            "signal_variance": [float(np.exp(gp.theta[dim])) for gp in gps],
            "noise_variance": [float(np.exp(gp.theta[dim + 1])) for gp in gps]}


def nmse(y, p):
    return 100.0 * np.sum((y - p) ** 2) / (len(y) * y.var())


def iterations(most, points, full_until=512, fewest=10):
    """`twin learn`'s refit_iterations: all up to `full_until` points, then the same work."""
    if points <= full_until:
        return most
    return int(min(most, max(min(fewest, most), np.ceil(most * (full_until / points) ** 3))))


def run(records, lags, transient, initial, refit_every, refit_growth, refit_iterations):
    streams = []
    for d, p in records:
        samples = np.column_stack([p["acc1"], p["acc2"], p["acc3"], d["force"]])
        t = d["time"]
        first = max(int(np.argmax(t - t[0] >= transient)), lags)
        meas = np.column_stack([d["acc1"], d["acc2"], d["acc3"]])
        phys = samples[:, :3]
        streams.append((t, lagged_inputs(samples, lags), meas - phys, meas, phys, first))
    t, x, y, meas, phys, first = streams[0]
    threshold = 1e-3 * meas[first:].var(0)
    started = time.perf_counter()
    end = first + initial
    rng = np.random.default_rng(0)
    gps = []
    for f in range(3):
        xs, ys = x[first:end], y[first:end, f]
        gps.append(Gp(xs, ys, fit(xs, ys, initial_starts(xs, ys, rng), 200)))
    out = []
    since_refit, points_at_fit = 0, initial
    refits = []
    for r, (t, x, y, meas, phys, first) in enumerate(streams):
        start = end if r == 0 else first
        queries, curve = [], []
        for k in range(start, len(t)):
            lat = [gp.latent(x[k:k + 1])[0] for gp in gps]
            if not any(v > th for v, th in zip(lat, threshold)):
                continue
            queries.append(float(t[k]))
            since_refit += 1
            refit = (refit_every > 0 and since_refit >= refit_every
                     and since_refit >= refit_growth * points_at_fit)
            for f, gp in enumerate(gps):
                gp.x = np.vstack([gp.x, x[k]])
                gp.y = np.append(gp.y, y[k, f])
                if refit:
                    gp.theta = fit(gp.x, gp.y, [gp.theta], iterations(refit_iterations, len(gp.y)))
                gp.factor()
            if refit:
                since_refit, points_at_fit = 0, len(gps[0].y)
                refits.append(describe(gps, r, len(queries), False))
            curve.append([nmse(meas[first:, f], phys[first:, f] + gps[f].mean(x[first:])) for f in range(3)])
        if refit_every > 0 and since_refit > 0:
            # As `twin learn`: the record's final GPs refitted to all that was learned in it.
            for gp in gps:
                gp.theta = fit(gp.x, gp.y, [gp.theta], iterations(refit_iterations, len(gp.y)))
                gp.factor()
            since_refit, points_at_fit = 0, len(gps[0].y)
            refits.append(describe(gps, r, len(queries), True))
        final = [nmse(meas[first:, f], phys[first:, f] + gps[f].mean(x[first:])) for f in range(3)]
        out.append({"queries": len(queries), "query_times": queries, "final_nmse": final})
    return time.perf_counter() - started, out, refits


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", nargs="+", required=True)
    ap.add_argument("--predictions", nargs="+", required=True)
    ap.add_argument("--lags", type=int, default=9)
    ap.add_argument("--transient", type=float, default=2.0)
    ap.add_argument("--initial", type=int, default=75)
    ap.add_argument("--refit-every", type=int, default=25)
    ap.add_argument("--refit-growth", type=float, default=1 / 3)
    ap.add_argument("--refit-iterations", type=int, default=100)
    ap.add_argument("--json")
    a = ap.parse_args()
    records = [(read_csv(d), read_csv(p)) for d, p in zip(a.data, a.predictions)]
    seconds, out, refits = run(records, a.lags, a.transient, a.initial, a.refit_every,
                               a.refit_growth, a.refit_iterations)
    result = {"seconds": seconds, "records": out, "refits": refits}
    print(json.dumps({"seconds": seconds, "queries": [r["queries"] for r in out],
                      "final_nmse": [[round(v, 3) for v in r["final_nmse"]] for r in out]}))
    if a.json:
        with open(a.json, "w") as f:
            json.dump(result, f)


if __name__ == "__main__":
    main()
