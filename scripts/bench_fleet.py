"""The fleet's throughput against workers (scripts/bench-fleet.sh).

Runs the same synthetic fleet (structures with hidden effects, each diagnosed and acted on)
on LocalClusters of 1 and 2 single-threaded worker processes and prints, per run: structures
per minute, the median task time, the overhead per task ((wall × workers − Σ task times) /
tasks); then the speed-up and the extrapolation to 100 workers from the task times.

The extrapolation: a fleet of F structures whose task times are the measured ones repeated,
each task plus the measured overhead o, list-scheduled on W workers, takes between
max(Σ(t + o) / W, max t) and Σ(t + o) / W + max t (Graham's bound); the throughput is F over
that, given for F = 1000 (so that the longest task does not decide it) as the range.
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
from pathlib import Path

from shear_twin import fleet


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--structures", type=int, default=8)
    p.add_argument("--duration", type=float, default=10.0)
    p.add_argument("--out", default="out/bench-fleet")
    a = p.parse_args()
    out = Path(a.out)
    manifest = fleet.make_synthetic_fleet(out / "fleet", a.structures, duration=a.duration, seed=5)
    runs = {}
    for workers in (1, 2):
        rows, summary = fleet.run_fleet(manifest, workers=workers)
        fleet.write_report(rows, summary, out / f"workers-{workers}")
        runs[workers] = (rows, summary)
        print(f"{workers} worker(s): {summary['structures']} structures in {summary['wall_seconds']:.1f} s = "
              f"{summary['throughput_per_minute']:.2f} structures/min; median task "
              f"{summary['task_seconds_median']:.2f} s (Σ {summary['task_seconds_total']:.1f} s); overhead "
              f"{summary['overhead_per_task_seconds']:.3f} s per task; actions {summary['actions']}")
    one, two = runs[1][1], runs[2][1]
    same = [(r["action"], r["nmse_after"]) for r in runs[1][0]] == [(r["action"], r["nmse_after"]) for r in runs[2][0]]
    print(f"speed-up 2 workers / 1: {two['throughput_per_minute'] / one['throughput_per_minute']:.2f}×; "
          f"results identical: {same}")
    times = [r["seconds"] for r in runs[1][0]]
    overhead = max(0.0, one["overhead_per_task_seconds"])
    fleet_size, workers = 1000, 100
    total = sum(times) * fleet_size / len(times) + overhead * fleet_size
    low = max(total / workers, max(times))
    high = total / workers + max(times)
    print(f"100 workers, a fleet of {fleet_size} (these task times repeated, + {overhead:.3f} s overhead each): "
          f"{60 * fleet_size / high:.0f}–{60 * fleet_size / low:.0f} structures/min "
          f"(1 worker: {60 * fleet_size / (total):.1f}); wall {low:.0f}–{high:.0f} s")
    (out / "bench.json").write_text(json.dumps({"1": one, "2": two, "overhead_used": overhead,
                                                "median_task": statistics.median(times)}, indent=2))


if __name__ == "__main__":
    main()
