"""Fleets: the twin's work for many structures as Dask tasks.

A manifest (JSON) lists the structures, each with its twin and record::

    {"seed": 1,
     "tasks": ["compare", "diagnose", "calibrate"], "calibrate_starts": 12,
     "structures": [{"name": "bridge-17", "twin": "twins/b17.ssp", "record": "b17/today.csv"}, ...]}

Paths are relative to the manifest. Per structure one task: compare the twin with the record
(NMSE before); with ``diagnose``, diagnose it and act — ``add_physics`` adds the effects found,
``recalibrate`` (with ``calibrate``) recalibrates with the structure's seed — and compare again
(NMSE after). A structure whose twin or data is bad gets the error in its row (the CLI's
message) and the fleet goes on. Tasks run on a ``dask.distributed`` cluster: a ``LocalCluster``
of ``workers`` single-threaded processes by default, or a running one (``scheduler=
"tcp://HOST:PORT"``). Each worker process keeps one twin per path open (its FMU's library
loaded once) for the tasks it runs. A worker that dies mid-task: the scheduler reruns its
tasks on another; every structure has exactly one row, whichever worker ran it.

``twin fleet MANIFEST.json [--scheduler tcp://HOST:PORT] [--workers N] [--out DIR]`` runs this
module; ``python -m shear_twin.fleet synth --out DIR --structures N`` makes a fleet of synthetic
structures with hidden effects.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import shear_twin as st

TASKS = ("compare", "diagnose", "calibrate")
COLUMNS = [
    "structure", "record", "action", "effect", "nmse_before", "nmse_after",
    "frequency_shift", "modes_moved", "seconds", "worker", "pid", "error",
]

# One twin per path and worker process, kept between tasks (keyed by path and modification
# time, so a rewritten archive is opened again).
_TWINS: dict[tuple[str, float], st.Twin] = {}


def _twin(path: str) -> st.Twin:
    key = (path, os.stat(path).st_mtime)
    twin = _TWINS.get(key)
    if twin is None:
        twin = st.Twin.open(path)
        _TWINS[key] = twin
    return twin


def load_manifest(path: str | os.PathLike) -> dict[str, Any]:
    """The manifest with paths made absolute, tasks checked and a seed per structure (the
    structure's own ``seed``, else the manifest's ``seed`` + its index)."""
    path = Path(path)
    with open(path) as f:
        manifest = json.load(f)
    base = path.resolve().parent
    tasks = manifest.get("tasks", list(TASKS))
    unknown = [t for t in tasks if t not in TASKS]
    if unknown:
        raise ValueError(f"{path}: unknown tasks {unknown}; known: {list(TASKS)}")
    structures = manifest.get("structures")
    if not structures:
        raise ValueError(f"{path}: no structures")
    seed = int(manifest.get("seed", 1))
    names = set()
    specs = []
    for i, s in enumerate(structures):
        for key in ("name", "twin", "record"):
            if key not in s:
                raise ValueError(f"{path}: structure {i} has no '{key}'")
        if s["name"] in names:
            raise ValueError(f"{path}: structure name '{s['name']}' appears twice")
        names.add(s["name"])
        specs.append({
            "name": s["name"],
            "twin": str(base / s["twin"]),
            "record": str(base / s["record"]),
            "seed": int(s.get("seed", seed + i)),
            "tasks": list(s.get("tasks", tasks)),
            "starts": int(manifest.get("calibrate_starts", 12)),
        })
    return {"tasks": tasks, "seed": seed, "structures": specs}


def _worst(nmse: list[float]) -> float:
    return max(nmse)


def _frequency_shift(modes: dict[str, Any] | None) -> tuple[float | None, str | None]:
    """From a compare report's ``modes``: the paired mode's frequency shift (%) largest in size,
    signed, and the twin modes that left their band (``"1,4"``; None when none did)."""
    if not modes or "modes" not in modes or not modes["modes"]:
        return None, None
    largest = max(modes["modes"], key=lambda m: abs(m["frequency_shift_percent"]))
    moved = ",".join(str(n) for n in modes.get("shifted") or []) or None
    return float(largest["frequency_shift_percent"]), moved


def run_structure(spec: dict[str, Any]) -> dict[str, Any]:
    """One structure's work (runs on a worker): its row of the fleet report."""
    started = time.perf_counter()
    row: dict[str, Any] = {k: None for k in COLUMNS}
    row.update(structure=spec["name"], record=spec["record"], pid=os.getpid())
    try:
        from distributed import get_worker
        row["worker"] = get_worker().address
    except (ImportError, ValueError):
        row["worker"] = "local"
    try:
        record = st.Record.read(spec["record"])
        twin = _twin(spec["twin"])
        before = twin.compare(record, modes=True)
        row["nmse_before"] = _worst(before.nmse)
        row["nmse_after"] = row["nmse_before"]
        row["frequency_shift"], row["modes_moved"] = _frequency_shift(before.to_dict().get("modes"))
        row["action"] = "compare"
        if "diagnose" in spec["tasks"]:
            diagnosis = twin.diagnose(record, threads=1)
            row["action"] = diagnosis.action
            effects = diagnosis.to_dict().get("effects") or []
            row["effect"] = ", ".join(e.get("label", e.get("kind", "?")) for e in effects) or None
            if diagnosis.action == "add_physics":
                new_twin, _ = twin.add_physics(record, diagnosis=diagnosis, threads=1)
                row["nmse_after"] = _worst(new_twin.compare(record).nmse)
            elif diagnosis.action == "recalibrate" and "calibrate" in spec["tasks"]:
                new_twin, _ = twin.calibrate(record, seed=spec["seed"], starts=spec["starts"], threads=1)
                row["nmse_after"] = _worst(new_twin.compare(record).nmse)
            elif diagnosis.action == "sensor_fault":
                sensor = diagnosis.to_dict().get("sensor") or {}
                row["effect"] = f"sensor floor {sensor.get('floor')}, gain {sensor.get('gain', float('nan')):.3f}"
        elif "calibrate" in spec["tasks"]:
            new_twin, _ = twin.calibrate(record, seed=spec["seed"], starts=spec["starts"], threads=1)
            row["action"] = "calibrate"
            row["nmse_after"] = _worst(new_twin.compare(record).nmse)
    except st.ShearTwinError as e:
        row["error"] = str(e)
    row["seconds"] = time.perf_counter() - started
    return row


def run_fleet(manifest: str | os.PathLike | dict[str, Any], *, scheduler: str | None = None,
              workers: int = 2, client: Any = None) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """Run a fleet on Dask: the rows (one per structure, in the manifest's order) and a summary
    (wall time, throughput, task times). ``client``: an existing ``distributed.Client``;
    else one on ``scheduler``, else on a ``LocalCluster`` of ``workers`` processes."""
    from distributed import Client, LocalCluster, as_completed

    if not isinstance(manifest, dict):
        manifest = load_manifest(manifest)
    specs = manifest["structures"]
    cluster = None
    own_client = client is None
    if own_client:
        if scheduler:
            client = Client(scheduler)
        else:
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                   host="127.0.0.1", dashboard_address=None)
            client = Client(cluster)
    try:
        n_workers = len(client.scheduler_info()["workers"])
        started = time.perf_counter()
        # pure=False: each structure's task is its own, and a rerun after a lost worker
        # replaces its result rather than adding one.
        futures = client.map(run_structure, specs, pure=False,
                             key=[f"structure-{i}-{s['name']}" for i, s in enumerate(specs)])
        index = {f.key: i for i, f in enumerate(futures)}
        rows: list[dict[str, Any] | None] = [None] * len(specs)
        for future, row in as_completed(futures, with_results=True):
            rows[index[future.key]] = row
        wall = time.perf_counter() - started
    finally:
        if own_client:
            client.close()
            if cluster is not None:
                cluster.close()
    assert all(r is not None for r in rows)
    return rows, summarise(rows, wall, n_workers)


def fleet(manifest: str | os.PathLike | dict[str, Any], *, scheduler: str | None = None,
          workers: int = 2, out: str | os.PathLike | None = None) -> tuple[Any, dict[str, Any]]:
    """``twin fleet MANIFEST [--scheduler …] [--workers N] [--out DIR]`` as a call: the fleet's
    rows as a pandas DataFrame (one per structure, in the manifest's order) and the summary;
    with ``out``, the report is written there too (fleet.csv, fleet.parquet,
    fleet-summary.json, fleet.svg). The CLI writes to ``out/fleet`` by default; here nothing is
    written unless ``out`` is given."""
    import pandas as pd

    rows, summary = run_fleet(manifest, scheduler=scheduler, workers=workers)
    if out is not None:
        write_report(rows, summary, out)
    return pd.DataFrame(rows, columns=COLUMNS), summary


def summarise(rows: list[dict[str, Any]], wall: float, workers: int) -> dict[str, Any]:
    """Throughput and overhead: ``overhead_per_task`` = (wall × workers − Σ task times) / tasks,
    the time a worker spends per task outside the task's own work (scheduling, transfer,
    idling at the end)."""
    times = [r["seconds"] for r in rows]
    total = sum(times)
    n = len(rows)
    return {
        "structures": n,
        "workers": workers,
        "wall_seconds": wall,
        "throughput_per_minute": 60.0 * n / wall,
        "task_seconds_total": total,
        "task_seconds_median": statistics.median(times),
        "overhead_per_task_seconds": (wall * workers - total) / n,
        "errors": sum(1 for r in rows if r["error"]),
        "actions": _count(r["action"] if r["action"] is not None else "error" for r in rows),
    }


def _count(labels) -> dict[str, int]:
    """How many of each label (a row that failed before its action counts as ``error``)."""
    counts: dict[str, int] = {}
    for label in labels:
        counts[label] = counts.get(label, 0) + 1
    return dict(sorted(counts.items()))


def write_report(rows: list[dict[str, Any]], summary: dict[str, Any], out: str | os.PathLike) -> None:
    """``fleet.csv``, ``fleet.parquet``, ``fleet-summary.json`` and ``fleet.svg`` in ``out``."""
    import pandas as pd

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    frame = pd.DataFrame(rows, columns=COLUMNS)
    frame.to_csv(out / "fleet.csv", index=False)
    frame.to_parquet(out / "fleet.parquet", index=False)
    (out / "fleet-summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    plot(frame, summary, out / "fleet.svg")


def plot(frame: Any, summary: dict[str, Any], path: Path) -> None:
    """Worst-floor NMSE before and after per structure (log scale), the action as the label,
    errors marked; the task time beside."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    n = len(frame)
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(max(8.0, 0.5 * n + 6), 4.5),
                                 gridspec_kw={"width_ratios": [3, 1]})
    x = np.arange(n)
    before = frame["nmse_before"].astype(float).to_numpy()
    after = frame["nmse_after"].astype(float).to_numpy()
    ax.bar(x - 0.2, before, 0.4, label="before", color="#c0504d")
    ax.bar(x + 0.2, after, 0.4, label="after", color="#4f81bd")
    ax.set_yscale("log")
    ax.set_xticks(x)
    labels = [f"{s}\n{'ERROR' if isinstance(e, str) else a}" for s, a, e in
              zip(frame["structure"], frame["action"], frame["error"])]
    ax.set_xticklabels(labels, rotation=60, ha="right", fontsize=7)
    ax.set_ylabel("worst-floor NMSE %")
    ax.legend()
    ax.set_title(f"fleet: {summary['structures']} structures, {summary['workers']} workers, "
                 f"{summary['throughput_per_minute']:.1f} structures/min")
    bx.hist(frame["seconds"].astype(float), bins=min(10, max(3, n // 2)), color="#9bbb59")
    bx.set_xlabel("task time, s")
    bx.set_ylabel("tasks")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


# ---------------------------------------------------------------------------------------------
# Synthetic fleets

#: The hidden effects of a synthetic fleet, in turn: (label, scenario fields).
HIDDEN = [
    ("none", {}),
    ("contact 2-3", {"effects": [{"kind": "contact", "location": [2, 3], "gap": 2e-4, "stiffness": 9000}]}),
    ("k2 -15 %", {"changes": [{"at": 0.0, "parameter": "k2", "factor": 0.85}]}),
    ("cubic storey 2", {"effects": [{"kind": "cubic", "location": [2], "stiffness": 5e9}]}),
]


def make_synthetic_fleet(out: str | os.PathLike, structures: int, *, duration: float = 12.0,
                         seed: int = 1, bad: int = 0) -> Path:
    """A fleet of synthetic structures of ``twin synth``'s frame, each with a hidden effect
    (``HIDDEN`` in turn) and its own force and noise (seeds ``seed``·1000 + i); one twin
    calibrated on a clean record of the unchanged frame; ``bad`` more structures whose record
    is malformed (a non-number on line 5). Returns the manifest's path."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    clean, _ = st.synth({"seed": seed, "duration": 20.0})
    twin, _ = st.Twin.default().calibrate(clean, seed=seed)
    twin.save(out / "twin.ssp")
    entries = []
    for i in range(structures):
        label, fields = HIDDEN[i % len(HIDDEN)]
        scenario = {"seed": seed * 1000 + i, "duration": duration, **fields}
        name = f"s{i:03d}"
        _, truth = st.synth(scenario, out=str(out / f"{name}.csv"))
        entries.append({"name": name, "twin": "twin.ssp", "record": f"{name}.csv", "hidden": label})
    for j in range(bad):
        name = f"bad{j:02d}"
        lines = (out / "s000.csv").read_text().splitlines()
        lines[4] = lines[4].replace(",", ",oops", 1)
        (out / f"{name}.csv").write_text("\n".join(lines) + "\n")
        entries.append({"name": name, "twin": "twin.ssp", "record": f"{name}.csv", "hidden": "bad data"})
    manifest = out / "manifest.json"
    manifest.write_text(json.dumps({"seed": seed, "tasks": list(TASKS), "structures": entries}, indent=2) + "\n")
    return manifest


# ---------------------------------------------------------------------------------------------
# Command line (`twin fleet` runs this)

def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["synth"]:
        p = argparse.ArgumentParser(prog="twin fleet synth",
                                    description="Make a fleet of synthetic structures with hidden effects.")
        p.add_argument("--out", required=True)
        p.add_argument("--structures", type=int, default=8)
        p.add_argument("--duration", type=float, default=12.0)
        p.add_argument("--seed", type=int, default=1)
        p.add_argument("--bad", type=int, default=0, help="structures with a malformed record")
        a = p.parse_args(argv[1:])
        print(make_synthetic_fleet(a.out, a.structures, duration=a.duration, seed=a.seed, bad=a.bad))
        return 0
    p = argparse.ArgumentParser(prog="twin fleet", description=__doc__.split("\n\n")[0])
    p.add_argument("manifest")
    p.add_argument("--scheduler", help="tcp://HOST:PORT of a running `dask scheduler`")
    p.add_argument("--workers", type=int, default=2, help="LocalCluster worker processes (default 2)")
    p.add_argument("--out", default="out/fleet", help="report directory (default out/fleet)")
    a = p.parse_args(argv)
    try:
        manifest = load_manifest(a.manifest)
    except (OSError, ValueError) as e:
        print(f"twin fleet: error: {e}", file=sys.stderr)
        return 1
    rows, summary = run_fleet(manifest, scheduler=a.scheduler, workers=a.workers)
    write_report(rows, summary, a.out)
    for r in rows:
        result = (f"ERROR {r['error']}" if r["error"] else
                  f"{r['action']:<18} {r['effect'] or '':<28} NMSE {r['nmse_before']:.3f} → {r['nmse_after']:.3f} %")
        print(f"{r['structure']:<12} {result}  ({r['seconds']:.1f} s)")
    print(f"{summary['structures']} structures on {summary['workers']} workers in {summary['wall_seconds']:.1f} s: "
          f"{summary['throughput_per_minute']:.1f} structures/min, median task {summary['task_seconds_median']:.2f} s, "
          f"overhead {summary['overhead_per_task_seconds']:.3f} s per task, {summary['errors']} errors")
    print(f"wrote {a.out}/fleet.csv, fleet.parquet, fleet-summary.json, fleet.svg")
    return 0


if __name__ == "__main__":
    sys.exit(main())
