#!/usr/bin/env python3
"""Cost with N and with the record's length (issue 36, "Measure first"): `twin compare`,
`twin calibrate`, `twin diagnose` and `twin watch` on N-storey shear buildings (default N = 3, 10,
20) and records of 1024, 16384 and 131072 samples at 51.2 Hz (20 s, 320 s, 2560 s), each against
the numpy/scipy peers of scripts/bench_storeys.py where there is one, plus the real-size cases and
the paper rig's diagnosis; the issue's targets as PASS/FAIL lines.

The buildings, records and peers are bench_storeys.py's (imported, not copied): per N the twin
`twin init --storeys N --excitation force:1 --nominal` (every floor 5.2 kg, storey 3 N s/m,
4021 N/m), the truth the nominal perturbed (bench_storeys.truth_of), records by `twin synth` of
the truth: a band-limited force at floor 1, every floor measured, seed 1 (linear: the calibration
record) and seed 2 with a hidden cubic spring in storey 1 (bench_storeys.CUBIC: the diagnosis
record, also the one compared and watched). The twin used by compare, diagnose and watch is
`twin calibrate` (default starts) on the 1024-sample seed-1 record, at every length.

Real-size cases:
- contact: a 4-storey frame at 322.58 Hz, 8192 samples, force at floor 1, four accelerometers;
  the twin calibrated on a baseline record (seed 1, linear), then compared, diagnosed and watched
  on a record with a contact between floors 3 and 4 (CONTACT: the truth's linear model has a
  worst-floor NMSE of about 30 % on it);
- roving: a 3-storey frame, two 15,000-sample runs at 500 Hz (30 s), force at floor 1, one
  accelerometer a run (acc1, then acc2), `twin calibrate --data RUN1.csv RUN2.csv` from the
  nominal twin, against the peer's MAP over both runs (bench_storeys.Map with one channel per run:
  the parameters shared, each run its force and its noise variance);
- rig: `twin calibrate --data data/dataset1.csv` (the paper's default twin), then the timed
  `twin diagnose --data data/dataset3.csv`.

What is timed (wall clock of whole `twin` processes; the peers in-process as bench_storeys times
them; medians of --repetitions runs, ours and the peer interleaved in the same run):
- compare: `twin compare --twin CAL.ssp --data R.csv --report X.json --predictions P.csv` (one
  untimed run first) vs bench_storeys.peer_compare(..., "lsim");
- calibrate: `twin calibrate --starts 1` and with the default starts (12) on the seed-1 record of
  that length, vs bench_storeys.peer_calibrate with the same starts; both optima scored with
  bench_storeys' one formula J (the smaller the better posterior);
- diagnose: `twin diagnose --twin CAL.ssp --data R.csv --report D.json`, its action and effect. NO
  FULL PEER (as in bench_storeys: the nonlinear candidates are ours only); the peer column is
  bench_storeys' peer of the recalibration job alone (8 starts, one process), against the
  report's recalibration seconds;
- watch: `twin watch --no-diagnosis --twin CAL.ssp --source R.csv --alerts A.jsonl`: seconds a
  sample and × real time (the record's duration / the wall time). No peer.

A single run longer than --max-seconds is stopped (its process group killed), not repeated, and
shown as "> S s". The peers' calibrations run in a child process for that reason. A point whose
setup calibration (the twin the others need) is slow is still waited for.

Run through scripts/bench-scale.sh.
"""

from __future__ import annotations

import os

# The peers' numpy/scipy on one BLAS thread (their children inherit it): their matrices are small
# (2N ≤ 40 states) and their starts run in processes of their own, so more BLAS threads only
# spin against each other — one scipy start at 3 storeys took 0.70 s with OpenBLAS's threads on
# a busy machine and 0.09 s on one.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import datetime  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import pickle  # noqa: E402
import platform  # noqa: E402
import signal as signals  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_storeys as bs  # noqa: E402

RATE = 51.2
DEFAULT_STARTS = 12
CONTACT = "contact@3-4:gap=8e-5,stiffness=20000"
CONTACT_RATE, CONTACT_SAMPLES = 322.58, 8192
ROVING_RATE, ROVING_SECONDS = 500.0, 30.0
COMMANDS = ("compare", "calibrate", "diagnose", "watch")
CASES = ("contact", "roving", "rig")
ROOT = Path(__file__).resolve().parent.parent


# -- running with a time cap ----------------------------------------------------------------------
def wait_for(binary: str) -> None:
    """`twin` may be missing for a moment while it is rebuilt: wait for it (up to 10 minutes)."""
    for _ in range(600):
        if os.access(binary, os.X_OK):
            return
        time.sleep(1)
    raise SystemExit(f"{binary}: missing for 10 minutes")


def timed(cmd: list[str], cap: float) -> float | None:
    """Wall seconds of a whole process; None when it ran past `cap` (its process group killed)."""
    wait_for(cmd[0])
    t = time.perf_counter()
    p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True)
    try:
        _, err = p.communicate(timeout=cap)
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, signals.SIGKILL)
        p.communicate()
        return None
    if p.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({p.returncode}):\n{err.decode()[-2000:]}")
    return time.perf_counter() - t


def peer_job(job: dict, work: Path, cap: float) -> dict | None:
    """A peer calibration in a child process (its own pool), so that it can be stopped at `cap`."""
    path = work / f"job-{time.monotonic_ns()}.pkl"
    path.write_bytes(pickle.dumps(job))
    began = time.perf_counter()
    p = subprocess.Popen([sys.executable, __file__, "--peer-job", str(path)], start_new_session=True)
    try:
        p.wait(timeout=cap)
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, signals.SIGKILL)
        p.wait()
        return None
    process = time.perf_counter() - began
    if p.returncode != 0:
        raise PeerFailed(f"peer job {job['kind']} failed ({p.returncode})")
    # The job's process end to end (python, numpy/scipy imported, the record read, the fit):
    # what a user of the peer waits for, as a user of ours waits for `twin calibrate`.
    return {**pickle.loads(path.with_suffix(".out").read_bytes()), "process_seconds": process}


class PeerFailed(Exception):
    pass


class Run:
    """One run of a roving test: time, force and the measured acc<i> columns (any subset)."""

    def __init__(self, path: Path):
        table = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
        header = [h.split(" ")[0] for h in path.open().readline().strip().split(",")]
        self.floors = [int(h[3:]) - 1 for h in header[2:]]
        self.time, self.force, self.acc = table[:, 0], table[:, 1], table[:, 2:].T.copy()
        self.n = len(self.time)
        self.dt = 1.0 / round(1.0 / ((self.time[-1] - self.time[0]) / (self.n - 1)), 3)
        self.first = int(np.nonzero(self.time - self.time[0] >= bs.TRANSIENT)[0][0])
        self.after = np.arange(self.first, self.n)


class RovingMap(bs.Map):
    """bench_storeys.Map over several runs of one structure (runs of equal length): each run its
    own force and measured floors, one noise variance per run and channel, the parameters shared."""

    def __init__(self, runs: list[Run], storeys: int, priors: list[dict]):
        self.runs, self.storeys, self.priors = runs, storeys, priors
        self.samples = runs[0].after
        self.y = np.vstack([r.acc[:, self.samples] for r in runs])
        self.nf = self.y.shape[0]
        self.count = len(self.samples)
        self.mu = np.concatenate([np.log(bs.NOISE_FRACTION * r.acc[:, r.first:].var(axis=1)) for r in runs])
        self.simulations = 0

    def predict(self, z):
        self.simulations += 1
        v = self.values(z)
        n = self.storeys
        m, c, k = v[:n], v[n:2 * n], v[2 * n:]
        if np.any(m <= 0) or np.any(k < 0):
            return None
        y = np.vstack([bs.simulate(m, c, k, r.force, r.dt)[r.floors] for r in self.runs])
        return y if np.all(np.isfinite(y)) else None


def _init_roving(runs, storeys, priors):
    bs._MAP = RovingMap(runs, storeys, priors)


def peer_roving(runs: list[Run], storeys: int, priors: list[dict], starts: int, workers: int, seed: int) -> dict:
    """bench_storeys.peer_calibrate's starts and pool over RovingMap."""
    from concurrent.futures import ProcessPoolExecutor
    started = time.perf_counter()
    p = len(priors)
    draws = np.random.default_rng(seed).standard_normal((max(starts - 1, 0), p)) * 3.0
    z0 = [np.zeros(p)] + list(draws)
    if workers > 1:
        with ProcessPoolExecutor(max_workers=workers, initializer=_init_roving, initargs=(runs, storeys, priors)) as pool:
            fits = list(pool.map(bs._start, z0, chunksize=1))
    else:
        _init_roving(runs, storeys, priors)
        fits = [bs._start(z) for z in z0]
    best = min(fits, key=lambda f: f["j"])
    return {"seconds": time.perf_counter() - started, "j": best["j"], "simulations": sum(f["simulations"] for f in fits)}


def do_peer_job(path: Path) -> None:
    job = pickle.loads(path.read_bytes())
    if job["kind"] == "roving":
        out = peer_roving([Run(Path(p)) for p in job["data"]], job["storeys"], job["priors"], job["starts"],
                          job["workers"], 1)
    else:
        rec = bs.Record(Path(job["data"]), job["storeys"])
        samples = rec.after if job["samples"] == "after" else rec.fitted
        out = bs.peer_calibrate(rec, job["priors"], samples, job["starts"], job["workers"], seed=1)
        out = {k: out[k] for k in ("seconds", "j", "simulations")}
    path.with_suffix(".out").write_bytes(pickle.dumps(out))


# -- the bench ------------------------------------------------------------------------------------
class Bench:
    def __init__(self, args, work: Path, cpus: int):
        self.a, self.work, self.cpus = args, work, cpus
        self.twin, self.cap, self.reps = args.twin, args.max_seconds, args.repetitions
        self.rows: dict[str, list[dict]] = {c: [] for c in COMMANDS}
        self.extra: dict[str, dict] = {}

    def log(self, msg: str) -> None:
        print(msg, file=sys.stderr, flush=True)

    def series(self, label: str, ours_cmd, peer=None) -> dict:
        """Interleaved repetitions of ours (a command, or a callable returning seconds or None) and
        the peer (a callable returning (seconds or None, info)); a side past the cap stops."""
        ours, peers, info = [], [], None
        ours_over = peer_over = peer_failed = False
        for i in range(self.reps):
            if not ours_over:
                t = ours_cmd() if callable(ours_cmd) else timed(ours_cmd, self.cap)
                if t is None:
                    ours_over = True
                else:
                    ours.append(t)
            if peer is not None and not peer_over:
                try:
                    t, got = peer()
                except PeerFailed as e:
                    self.log(f"{label}: {e} (its traceback above); the peer is shown 'failed'")
                    t, got, peer_failed = None, None, True
                if t is None:
                    peer_over = True
                else:
                    peers.append(t)
                    info = got
            self.log(f"{label} {i + 1}/{self.reps}: ours {fmt_runs(ours, ours_over, self.cap)}"
                     + (f", peer {'failed' if peer_failed and not peers else fmt_runs(peers, peer_over, self.cap)}"
                        if peer is not None else ""))
            if (ours_over or not ours) and (peer is None or peer_over):
                break
        return {"ours": None if not ours else float(np.median(ours)), "ours_runs": ours, "ours_over": ours_over and not ours,
                "peer": None if not peers else float(np.median(peers)), "peer_runs": peers,
                "peer_over": peer_over and not peers and not peer_failed, "peer_failed": peer_failed and not peers,
                "peer_info": info}

    # one building, one length
    def grid_point(self, n: int, samples: int, b1: dict, cal_ssp: Path, cal_priors: list[dict]) -> None:
        skip = self.a.skip
        if samples == 1024:
            b = b1
        else:
            b = bs.building(self.twin, self.work, n, duration=samples / RATE, sample_rate=RATE, name=f"n{n}-{samples}")
        d = b["dir"]
        label = f"N={n} samples={samples}"
        if "compare" not in skip:
            pred, rep = d / "pred.csv", d / "compare.json"
            cmd = [self.twin, "compare", "--twin", str(cal_ssp), "--data", str(b["diag"]), "--report", str(rep),
                   "--predictions", str(pred)]
            warm = timed(cmd, self.cap)

            def lsim():
                t = time.perf_counter()
                bs.peer_compare(cal_ssp, b["diag"], n, d / "peer-lsim.csv", "lsim")
                return time.perf_counter() - t, None

            if warm is None:
                r = {"ours": None, "ours_over": True, "ours_runs": [], "peer": None, "peer_over": False}
                t, _ = lsim()
                r.update(peer=t, peer_runs=[t])
            else:
                r = self.series(f"{label} compare", cmd, lsim)
            self.rows["compare"].append({"storeys": n, "samples": samples, **r})
        if "calibrate" not in skip:
            rec = None
            for starts in self.a.starts:
                out, rep = d / f"cal-s{starts}.ssp", d / f"cal-s{starts}.json"
                cmd = [self.twin, "calibrate", "--twin", str(b["init"]), "--data", str(b["cal"]), "--starts",
                       str(starts), "--out", str(out), "--report", str(rep)]
                job = {"kind": "calibrate", "data": str(b["cal"]), "storeys": n, "priors": cal_priors,
                       "samples": "after", "starts": starts, "workers": min(self.cpus, starts)}

                peer_processes: list[float] = []

                def peer(job=job, peer_processes=peer_processes):
                    got = peer_job(job, self.work, self.cap)
                    if got is None:
                        return None, None
                    peer_processes.append(got["process_seconds"])
                    return got["seconds"], got

                fits: list[float] = []

                def ours(cmd=cmd, rep=rep, fits=fits):
                    t = timed(cmd, self.cap)
                    if t is not None:
                        fits.append(json.loads(rep.read_text())["seconds"])
                    return t

                r = self.series(f"{label} calibrate --starts {starts}", ours, peer)
                r["ours_fit"] = float(np.median(fits)) if fits else None
                r["peer_process"] = float(np.median(peer_processes)) if peer_processes else None
                if r["ours"] is not None:
                    report = json.loads(rep.read_text())
                    rec = rec or bs.Record(b["cal"], n)
                    problem = bs.Map(rec, cal_priors, rec.after)
                    z = problem.coordinates([p["value"] for p in report["parameters"]])
                    r["ours_j"] = problem.j(z, np.log(np.array(report["noise_variance"])))
                    r["ours_nmse"] = max(report["nmse"])
                if r["peer_info"] is not None:
                    r["peer_j"] = r["peer_info"]["j"]
                r.pop("peer_info", None)
                self.rows["calibrate"].append({"storeys": n, "samples": samples, "starts": starts, **r})
        if "diagnose" not in skip:
            r = self.diagnose(label, cal_ssp, b["diag"], n, d, recal_peer=True, priors=cal_priors)
            self.rows["diagnose"].append({"storeys": n, "samples": samples, **r})
        if "watch" not in skip:
            r = self.watch(label, cal_ssp, b["diag"], d, samples, samples / RATE)
            self.rows["watch"].append({"storeys": n, "samples": samples, **r})

    def diagnose(self, label, cal_ssp: Path, data: Path, n: int, d: Path, recal_peer: bool,
                 priors: list[dict] | None = None) -> dict:
        state = {}

        def ours():
            r = d / "diagnose.json"
            t = timed([self.twin, "diagnose", "--twin", str(cal_ssp), "--data", str(data), "--report", str(r)], self.cap)
            if t is not None:
                state["report"] = json.loads(r.read_text())
            return t

        def peer():
            # The recalibration's priors are the twin's calibration's (the diagnosis reports the
            # moves, not the priors): the grid point's setup calibration gives them.
            dg = state.get("report")
            if dg is None or dg.get("recalibration") is None or priors is None:
                raise PeerFailed("no recalibration or no priors to run the peer with")
            got = peer_job({"kind": "calibrate", "data": str(data), "storeys": n, "priors": priors, "samples": "fitted",
                            "starts": bs.RECALIBRATION_STARTS, "workers": 1}, self.work, self.cap)
            return (None, None) if got is None else (got["seconds"], got)

        r = self.series(f"{label} diagnose", ours, peer if recal_peer else None)
        r.pop("peer_info", None)
        dg = state.get("report")
        if dg is not None:
            r.update(action=dg["action"], effect=(dg.get("effect") or {}).get("label"),
                     nmse_before=max(dg["nmse_before"]),
                     nmse_after=max(dg["nmse_after"]) if dg.get("nmse_after") else None,
                     recal_ours=(dg.get("recalibration") or {}).get("seconds"))
        return r

    def watch(self, label, cal_ssp: Path, data: Path, d: Path, samples: int, duration: float) -> dict:
        cmd = [self.twin, "watch", "--no-diagnosis", "--twin", str(cal_ssp), "--source", str(data), "--alerts",
               str(d / "alerts.jsonl")]
        r = self.series(f"{label} watch", cmd)
        r["per_sample"] = None if r["ours"] is None else r["ours"] / samples
        r["real_time"] = None if r["ours"] is None else duration / r["ours"]
        r["duration"] = duration
        r["own_real_time"] = None
        alerts = d / "alerts.jsonl"
        if r["ours"] is not None and alerts.exists():
            ends = [json.loads(x) for x in alerts.read_text().splitlines() if '"kind":"end"' in x.replace(" ", "")]
            r["own_real_time"] = ends[-1].get("real_time_factor") if ends else None
        return r

    def calibrate_setup(self, init: Path, data: list[Path], out: Path, report: Path, starts: int | None = None
                        ) -> tuple[float, dict]:
        wait_for(self.twin)
        t = time.perf_counter()
        more = [] if starts is None else ["--starts", str(starts)]
        subprocess.run([self.twin, "calibrate", "--twin", str(init), "--data", *map(str, data), "--out", str(out),
                        "--report", str(report), *more], check=True, stdout=subprocess.DEVNULL)
        return time.perf_counter() - t, json.loads(report.read_text())

    # the real-size cases
    def contact(self) -> None:
        n = 4
        b = bs.building(self.twin, self.work, n, duration=CONTACT_SAMPLES / CONTACT_RATE, sample_rate=CONTACT_RATE,
                        effect=CONTACT, name="contact")
        d = b["dir"]
        cal_ssp = d / "cal.ssp"
        self.log(f"contact: calibrating the 4-storey twin on the {CONTACT_SAMPLES}-sample baseline (untimed setup) ...")
        secs, _ = self.calibrate_setup(b["init"], [b["cal"]], cal_ssp, d / "cal.json")
        rec = bs.Record(b["diag"], n)
        truth = b["truth"]
        linear = bs.simulate(truth["m"], truth["c"], truth["k"], rec.force, rec.dt)
        out = {"calibrate_setup_s": secs, "truth_linear_nmse": float(max(bs.nmse(rec.acc[:, rec.first:], linear[:, rec.first:])))}
        label = f"contact N=4 samples={CONTACT_SAMPLES}"
        if "compare" not in self.a.skip:
            pred, rep = d / "pred.csv", d / "compare.json"
            cmd = [self.twin, "compare", "--twin", str(cal_ssp), "--data", str(b["diag"]), "--report", str(rep),
                   "--predictions", str(pred)]
            timed(cmd, self.cap)

            def lsim():
                t = time.perf_counter()
                bs.peer_compare(cal_ssp, b["diag"], n, d / "peer-lsim.csv", "lsim")
                return time.perf_counter() - t, None

            r = self.series(f"{label} compare", cmd, lsim)
            out["compare_nmse"] = max(json.loads(rep.read_text())["nmse"]) if rep.exists() else None
            self.rows["compare"].append({"storeys": "4c", "samples": CONTACT_SAMPLES, **r})
        if "diagnose" not in self.a.skip:
            r = self.diagnose(label, cal_ssp, b["diag"], n, d, recal_peer=False)
            self.rows["diagnose"].append({"storeys": "4c", "samples": CONTACT_SAMPLES, **r})
            out["diagnose"] = r
        if "watch" not in self.a.skip:
            r = self.watch(label, cal_ssp, b["diag"], d, CONTACT_SAMPLES, CONTACT_SAMPLES / CONTACT_RATE)
            self.rows["watch"].append({"storeys": "4c", "samples": CONTACT_SAMPLES, **r})
        self.extra["contact"] = out

    def roving(self) -> None:
        n = 3
        d = self.work / "roving"
        d.mkdir()
        init = d / "init.ssp"
        (d / "nominal.json").write_text(json.dumps({f: [bs.NOMINAL[f]] * n for f in "mck"}))
        subprocess.run([self.twin, "init", "--storeys", str(n), "--excitation", "force:1", "--nominal",
                        str(d / "nominal.json"), "--out", str(init)], check=True, stdout=subprocess.DEVNULL)
        base = bs.synth_command(self.twin, n, bs.truth_of(n), ROVING_SECONDS, ROVING_RATE)
        runs = []
        for i in (1, 2):
            runs.append(d / f"run{i}.csv")
            subprocess.run(base + ["--seed", str(i), "--channels", f"acc{i}", "--out", str(runs[-1])], check=True,
                           stdout=subprocess.DEVNULL)
        samples = Run(runs[0]).n
        # The peer takes ours' priors (the nominal twin's): read from a --starts 1 calibration of the
        # same twin on a 20 s record of every floor (seconds), so the peer runs even when ours is capped.
        pb = bs.building(self.twin, self.work, n, name="roving-priors")
        _, prep = self.calibrate_setup(pb["init"], [pb["cal"]], pb["dir"] / "cal.ssp", pb["dir"] / "cal.json", starts=1)
        priors = [p["prior"] for p in prep["parameters"]]
        out = {}
        for starts in (1, DEFAULT_STARTS):
            rep = d / f"cal-s{starts}.json"
            cmd = [self.twin, "calibrate", "--twin", str(init), "--data", *map(str, runs), "--starts", str(starts),
                   "--out", str(d / f"cal-s{starts}.ssp"), "--report", str(rep)]
            state = {"fits": []}

            def ours(cmd=cmd, rep=rep):
                t = timed(cmd, self.cap)
                if t is not None:
                    state["report"] = json.loads(rep.read_text())
                    state["fits"].append(state["report"]["seconds"])
                return t

            def peer(starts=starts):
                got = peer_job({"kind": "roving", "data": [str(p) for p in runs], "storeys": n, "priors": priors,
                                "starts": starts, "workers": min(self.cpus, starts)}, self.work, self.cap)
                return (None, None) if got is None else (got["seconds"], got)

            r = self.series(f"roving calibrate --starts {starts}", ours, peer)
            r["ours_fit"] = float(np.median(state["fits"])) if state["fits"] else None
            if "report" in state:
                report = state["report"]
                problem = RovingMap([Run(p) for p in runs], n, priors)
                z = problem.coordinates([p["value"] for p in report["parameters"]])
                s = np.log(np.array([v for run in report["runs"] for v in run["noise_variance"].values()]))
                r["ours_j"] = problem.j(z, s)
            if r["peer_info"] is not None:
                r["peer_j"] = r["peer_info"]["j"]
            r.pop("peer_info", None)
            self.rows["calibrate"].append({"storeys": "3r", "samples": f"2×{samples}", "starts": starts, **r})
            out[starts] = r
        self.extra["roving"] = out

    def rig(self) -> None:
        d = self.work / "rig"
        d.mkdir()
        cal = d / "cal.ssp"
        t = time.perf_counter()
        subprocess.run([self.twin, "calibrate", "--data", str(ROOT / "data/dataset1.csv"), "--out", str(cal),
                        "--report", str(d / "cal.json")], check=True, stdout=subprocess.DEVNULL)
        secs = time.perf_counter() - t
        r = self.diagnose("rig dataset3", cal, ROOT / "data/dataset3.csv", 3, d, recal_peer=False)
        r["calibrate_setup_s"] = secs
        self.rows["diagnose"].append({"storeys": "3 rig", "samples": 1024, **r})
        self.extra["rig"] = r


def fmt_runs(xs, over, cap):
    s = ", ".join(f"{x:.2f}" for x in xs)
    return s + (f"{', ' if s else ''}> {cap:g} s" if over else "")


def cell(r: dict, side: str, cap: float, width: int = 9) -> str:
    if r.get(side) is not None:
        v = r[side]
        return f"{v:{width}.3f}" if v < 10 else f"{v:{width}.1f}"
    if r.get(f"{side}_over"):
        return f"{'> ' + format(cap, 'g') + ' s':>{width}}"
    if r.get(f"{side}_failed"):
        return f"{'failed':>{width}}"
    return f"{'—':>{width}}"


def ratio(r: dict) -> str:
    if r.get("ours") is not None and r.get("peer") is not None:
        return f"{r['peer'] / r['ours']:7.2f}"
    return f"{'—':>7}"


def report(bench: Bench, args, cpus: int, total: float) -> None:
    cap = args.max_seconds
    rows = bench.rows
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    print()
    print(f"Cost with N and length: {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC, {platform.node()}, "
          f"{cpus} CPUs, load average now {load} (shared: other work slows both sides); medians of "
          f"{args.repetitions} runs, ours and the peer interleaved; a single run past {cap:g} s stopped and shown "
          f"'> {cap:g} s'; bench {total / 60:.1f} min")
    print(f"grid: N = {' '.join(map(str, args.storeys))} storeys × {' '.join(map(str, args.lengths))} samples at "
          f"{RATE} Hz, force at floor 1, every floor measured; N = 4c: the contact case ({CONTACT_SAMPLES} samples at "
          f"{CONTACT_RATE} Hz, {CONTACT}); 3r: the two roving runs; seconds, wall clock; ratio = peer / ours")
    head = f"{'N':>6} {'samples':>9} | {'ours s':>9} {'peer s':>9} {'ratio':>7}"
    if rows["compare"]:
        print("\ncompare: `twin compare --report --predictions` (process) vs scipy.signal.lsim (peer_compare, in process)")
        print(head)
        for r in rows["compare"]:
            print(f"{r['storeys']!s:>6} {r['samples']!s:>9} | {cell(r, 'ours', cap)} {cell(r, 'peer', cap)} {ratio(r)}")
    if rows["calibrate"]:
        print("\ncalibrate: `twin calibrate --starts S` (every core) vs least_squares(lm) MAP (peer_calibrate, S starts, "
              f"{cpus} processes); J: bench_storeys' one formula (lower = better posterior)")
        print("  'fit s': the calibration in our process (the report's seconds: records in memory, the twin not yet "
              "written), as the peer's seconds are its fit in its process; 'fit ×' = peer / fit s")
        print("  'proc s': the peer's process end to end (python started, numpy/scipy imported, the record read, "
              "the fit), as ours is; 'proc ×' = proc s / ours s")
        print(f"{head} {'fit s':>9} {'fit ×':>7} {'proc s':>8} {'proc ×':>7} {'starts':>6} {'J ours':>12} {'J peer':>12}")
        for r in rows["calibrate"]:
            jo = f"{r['ours_j']:12.2f}" if r.get("ours_j") is not None else f"{'—':>12}"
            jp = f"{r['peer_j']:12.2f}" if r.get("peer_j") is not None else f"{'—':>12}"
            fit = r.get("ours_fit")
            fs = f"{fit:9.3f}" if fit else f"{'—':>9}"
            fr = f"{r['peer'] / fit:7.1f}" if fit and r.get("peer") is not None else f"{'—':>7}"
            proc = r.get("peer_process")
            ps = f"{proc:8.3f}" if proc else f"{'—':>8}"
            pr = f"{proc / r['ours']:7.1f}" if proc and r.get("ours") else f"{'—':>7}"
            print(f"{r['storeys']!s:>6} {r['samples']!s:>9} | {cell(r, 'ours', cap)} {cell(r, 'peer', cap)} {ratio(r)} "
                  f"{fs} {fr} {ps} {pr} {r['starts']:>6} {jo} {jp}"
                  + (f"  ({r['peer_note']})" if r.get("peer_note") else ""))
    if rows["diagnose"]:
        print("\ndiagnose: the whole `twin diagnose` (its default threads). NO FULL PEER: the nonlinear candidates are "
              "ours only; 'peer' is bench_storeys' peer of the recalibration job alone (8 starts, 1 process), its ratio "
              "against the report's recalibration seconds ('recal')")
        print(f"{'N':>6} {'samples':>9} | {'ours s':>9} {'recal s':>9} {'peer s':>9} {'ratio':>7} | "
              f"{'NMSE% before':>12} {'after':>8}  action / effect")
        for r in rows["diagnose"]:
            rc = r.get("recal_ours")
            rr = f"{r['peer'] / rc:7.2f}" if rc and r.get("peer") is not None else f"{'—':>7}"
            nb = f"{r['nmse_before']:12.1f}" if r.get("nmse_before") is not None else f"{'—':>12}"
            na = f"{r['nmse_after']:8.2f}" if r.get("nmse_after") is not None else f"{'—':>8}"
            act = f"{r.get('action') or '—'} {r.get('effect') or ''}".strip()
            print(f"{r['storeys']!s:>6} {r['samples']!s:>9} | {cell(r, 'ours', cap)} "
                  f"{(f'{rc:9.2f}' if rc else '—'.rjust(9))} {cell(r, 'peer', cap)} {rr} | {nb} {na}  {act}")
    if rows["watch"]:
        print("\nwatch: `twin watch --no-diagnosis --source R.csv` (no peer): seconds a sample, × real time = duration / "
              "wall (the whole process, start-up included); 'own ×' = the real-time factor watch reports in its end alert")
        print(f"{'N':>6} {'samples':>9} | {'ours s':>9} {'µs/sample':>10} {'× real':>9} {'own ×':>9}")
        for r in rows["watch"]:
            ps = f"{r['per_sample'] * 1e6:10.1f}" if r.get("per_sample") is not None else f"{'—':>10}"
            rt = f"{r['real_time']:9.0f}" if r.get("real_time") is not None else (
                f"{'< ' + format(r['duration'] / cap, '.3g'):>9}" if r.get("ours_over") else f"{'—':>9}")
            own = f"{r['own_real_time']:9.0f}" if r.get("own_real_time") else f"{'—':>9}"
            print(f"{r['storeys']!s:>6} {r['samples']!s:>9} | {cell(r, 'ours', cap)} {ps} {rt} {own}")
    if "contact" in bench.extra:
        c = bench.extra["contact"]
        print(f"\ncontact case: the truth's linear model's worst-floor NMSE on the contact record "
              f"{c['truth_linear_nmse']:.1f} %; the baseline calibration (setup) {c['calibrate_setup_s']:.1f} s"
              + (f"; the calibrated twin's worst-floor NMSE {c['compare_nmse']:.1f} %" if c.get("compare_nmse") else ""))
    if "rig" in bench.extra:
        print(f"rig: `twin calibrate --data data/dataset1.csv` (setup) {bench.extra['rig']['calibrate_setup_s']:.1f} s")
    targets(bench, cap)


def targets(bench: Bench, cap: float) -> None:
    rows = bench.rows
    print("\ntargets (issue 36):")

    def find(cmd, n, samples, **kw):
        for r in rows[cmd]:
            if r["storeys"] == n and r["samples"] == samples and all(r.get(k) == v for k, v in kw.items()):
                return r
        return None

    def line(name, ok, detail):
        verdict = "NOT MEASURED" if ok is None else ("PASS" if ok else "FAIL")
        print(f"  {verdict:<12} {name}: {detail}")

    def secs(r, side="ours"):
        if r is None:
            return None, "not measured"
        if r.get(side) is not None:
            return r[side], f"{r[side]:.2f} s"
        if r.get(f"{side}_over"):
            return math.inf, f"> {cap:g} s"
        return None, "not measured"

    for name, r, goal in (("diagnose, 3-storey 1024 samples (dataset3-like)", find("diagnose", 3, 1024), 3),
                          ("diagnose, paper rig dataset3 (data/dataset3.csv)", find("diagnose", "3 rig", 1024), 3),
                          (f"diagnose, 4-storey {CONTACT_SAMPLES} samples with contact", find("diagnose", "4c", CONTACT_SAMPLES), 15),
                          ("diagnose, 10-storey 1024 samples", find("diagnose", 10, 1024), 10),
                          ("diagnose, 20-storey 1024 samples", find("diagnose", 20, 1024), 20)):
        t, text = secs(r)
        line(name, None if t is None else t <= goal, f"{text} (≤ {goal} s)")
    ns = sorted({r["storeys"] for r in rows["diagnose"] if isinstance(r["storeys"], int)})
    any_linear = False
    for n in ns:
        small, big = find("diagnose", n, 1024), find("diagnose", n, 131072)
        if small is None or big is None:
            continue
        any_linear = True
        ts, _ = secs(small)
        tb, text = secs(big)
        if ts is None or tb is None:
            line(f"diagnose linear in length, N={n}", None, "not measured")
        else:
            line(f"diagnose linear in length, N={n}", tb <= 1.5 * 128 * ts,
                 f"131072 samples {text} vs 1.5 × 128 × {ts:.2f} s = {1.5 * 128 * ts:.0f} s")
    if not any_linear:
        line("diagnose linear in length (131072 ≤ 1.5 × 128 × 1024)", None, "needs --lengths 1024 131072")
    rv = find("calibrate", "3r", f"2×{int(ROVING_SECONDS * ROVING_RATE)}", starts=DEFAULT_STARTS)
    t, text = secs(rv)
    if t is None:
        line("calibrate, the two roving runs ≤ 10 s and ≥ 10× the peer", None, text)
    else:
        p, ptext = secs(rv, "peer")
        fast = t <= 10
        faster = None if p is None or t == math.inf else p / t >= 10
        ok = fast and bool(faster)
        ratio_text = (f"{p / t:.2f}×" if p not in (None, math.inf) and t != math.inf else
                      f"> {cap / t:.1f}× (the peer past the cap)" if p == math.inf and t != math.inf else "—")
        line("calibrate, the two roving runs ≤ 10 s and ≥ 10× the peer", ok if faster is not None or not fast else None,
             f"ours {text}, peer {ptext}, peer/ours {ratio_text}")
    cmp_rows = rows["compare"]
    if cmp_rows:
        bad = [r for r in cmp_rows if r.get("ours") is None or r.get("peer") is None or r["ours"] > r["peer"]]
        worst = max((r for r in cmp_rows if r.get("ours") and r.get("peer")), key=lambda r: r["ours"] / r["peer"], default=None)
        line("compare ≤ lsim at every point", not bad,
             f"{len(cmp_rows) - len(bad)} of {len(cmp_rows)} points" +
             (f"; worst N={worst['storeys']} {worst['samples']}: ours {worst['ours']:.3f} s, lsim {worst['peer']:.3f} s"
              if worst else ""))
    else:
        line("compare ≤ lsim at every point", None, "not measured")
    w20 = [r for r in rows["watch"] if r["storeys"] == 20]
    if not w20:
        line("watch ≥ 100× real time at N = 20", None, "needs --storeys 20")
    else:
        slow = [r for r in w20 if r.get("real_time") is None or r["real_time"] < 100]
        line("watch ≥ 100× real time at N = 20", not slow,
             "; ".join(f"{r['samples']} samples " + (f"{r['real_time']:.0f}×" if r.get("real_time") else f"> {cap:g} s")
                       for r in w20))


def main() -> None:
    if len(sys.argv) == 3 and sys.argv[1] == "--peer-job":
        do_peer_job(Path(sys.argv[2]))
        return
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--twin", required=True)
    parser.add_argument("--storeys", type=int, nargs="+", default=[3, 10, 20])
    parser.add_argument("--lengths", type=int, nargs="+", default=[1024, 16384, 131072], help="samples at 51.2 Hz")
    parser.add_argument("--repetitions", type=int, default=3, help="timed runs of each side (median)")
    parser.add_argument("--skip", default="", help=f"comma-separated: any of {','.join(COMMANDS + CASES)}")
    parser.add_argument("--max-seconds", type=float, default=600.0,
                        help="a single run longer than this is stopped, not repeated and shown as '> S s'")
    parser.add_argument("--starts", type=int, nargs="+", default=[1, DEFAULT_STARTS],
                        help="the calibrations' start counts at each grid point (the roving case runs 1 and 12)")
    parser.add_argument("--json", type=Path)
    parser.add_argument("--work", type=Path,
                        help="keep the buildings, records and twins in this directory (default: a temporary one)")
    args = parser.parse_args()
    args.skip = {s.strip() for s in args.skip.split(",") if s.strip()}
    unknown = args.skip - set(COMMANDS + CASES)
    if unknown:
        parser.error(f"--skip: unknown {sorted(unknown)} (any of {', '.join(COMMANDS + CASES)})")
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        if args.work:
            args.work.mkdir(parents=True, exist_ok=True)
            work = args.work
        bench = Bench(args, work, cpus)
        for n in args.storeys:
            b1 = bs.building(args.twin, bench.work, n)
            cal_ssp = b1["dir"] / "cal.ssp"
            bench.log(f"N={n}: calibrating the twin on the 1024-sample record (untimed setup) ...")
            secs, rep = bench.calibrate_setup(b1["init"], [b1["cal"]], cal_ssp, b1["dir"] / "cal.json")
            bench.log(f"N={n}: setup calibration {secs:.1f} s")
            priors = [p["prior"] for p in rep["parameters"]]
            for samples in args.lengths:
                bench.grid_point(n, samples, b1, cal_ssp, priors)
        if "contact" not in args.skip:
            bench.contact()
        if "roving" not in args.skip and "calibrate" not in args.skip:
            bench.roving()
        if "rig" not in args.skip and "diagnose" not in args.skip:
            bench.rig()
        total = time.perf_counter() - started
        report(bench, args, cpus, total)
        if args.json:
            args.json.write_text(json.dumps({"rows": bench.rows, "extra": bench.extra, "max_seconds": args.max_seconds},
                                            indent=2, default=str) + "\n")


if __name__ == "__main__":
    sys.exit(main())
