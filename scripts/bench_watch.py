"""`twin watch` on long streams: speed against real time, memory against stream length, and
how long after a change its alert comes. Driven by scripts/bench-watch.sh, which builds
`twin` and the FMUs and passes their paths.

What is measured (each `twin watch` is one process; its peak resident memory is GNU time's
`%M`):

1. The physics twin (calibrated on a 20 s synthetic record, seed 1) on a 1 h record (seed 2,
   184 320 samples) and on 24 h (4 423 680 samples: the hour repeated with its times shifted),
   both from a file: samples per second and the speed against real time (51.2 Hz), the
   per-sample latency the watcher measures itself, and the peak memory of each. Constant memory
   means the two peaks are the same to within the allocator's noise.
2. The same twin with a GP corrector (trained on every second sample of the calibration
   record) learning online with a budget of 256 points (`--budget`), on 1 h and on 3 h: the
   same figures.
3. The alert latency after a change: 60 s records with the second storey's stiffness stepped
   down at 30 s (by 15 %, 10 % and 5 %); the delay from the change to the `failing` alert, in
   seconds of the stream (what the operator waits), and the wall-clock time the watcher took
   for the sample that raised it (its per-sample latency bounds that).
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

RATE = 51.2
TIME = "/usr/bin/time"


def run(cmd, **kw):
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, **kw)


def watch(twin_bin, twin, source, alerts, extra=()):
    """Run `twin watch` under GNU time; (end alert, all alerts, peak RSS MiB, wall s). The
    peak comes from GNU time (the child's own, after exec: a fork's copy of this Python
    process would otherwise count)."""
    rss_file = alerts + ".rss"
    cmd = [TIME, "-f", "%M", "-o", rss_file, twin_bin, "watch", "--no-diagnosis", "--twin",
           twin, "--source", source, "--alerts", alerts, *extra]
    start = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - start
    rss = float(open(rss_file).read().split()[-1]) / 1024.0
    alerts = [json.loads(line) for line in open(alerts)]
    return alerts[-1], alerts, rss, wall


def repeat(hour_csv, out_csv, times):
    """The hour's samples `times` over, each copy's times shifted by the hour's length."""
    with open(hour_csv) as f:
        header = f.readline()
        rows = [line.split(",", 1) for line in f]
    period = len(rows) / RATE
    with open(out_csv, "w") as out:
        out.write(header)
        for k in range(times):
            shift = k * period
            out.writelines(f"{float(t) + shift:.6f},{rest}" for t, rest in rows)


def describe(label, end, rss, wall):
    rate = end["samples_per_second"]
    line = (f"{label:<34} {end['samples']:>9} samples  {rate:>11,.0f} samples/s = "
            f"{rate / RATE:>8,.0f}x real time  latency median {end['latency_median_us']:7.2f} us,"
            f" p99 {end['latency_p99_us']:8.2f} us  peak RSS {rss:7.1f} MiB  wall {wall:6.1f} s")
    learning = end.get("learning")
    if learning:
        line += (f"\n{'':34} corrector: {learning['queries']} queries, "
                 f"{learning['training_points']} training points (budget {learning['budget']})")
    print(line, flush=True)
    return {"samples": end["samples"], "samples_per_second": rate,
            "real_time_factor": rate / RATE, "latency_median_us": end["latency_median_us"],
            "latency_p99_us": end["latency_p99_us"], "peak_rss_mib": rss, "wall_s": wall,
            "learning": learning}


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--twin-bin", required=True)
    p.add_argument("--corrector-hours", type=int, default=3)
    p.add_argument("--json")
    p.add_argument("--budget", type=int, default=256)
    a = p.parse_args()
    if not os.path.exists(TIME):
        sys.exit("GNU time (/usr/bin/time) measures the peak memory: apt-get install time")
    tw = a.twin_bin
    results = {}
    with tempfile.TemporaryDirectory() as d:
        j = lambda name: os.path.join(d, name)
        run([tw, "synth", "--seed", "1", "--duration", "20", "--out", j("calibration.csv")])
        run([tw, "calibrate", "--data", j("calibration.csv"), "--out", j("twin.ssp"),
             "--starts", "2"])
        run([tw, "train", "--twin", j("twin.ssp"), "--data", j("calibration.csv"),
             "--stride", "2", "--out", j("corrected.ssp")])
        run([tw, "synth", "--seed", "2", "--duration", "3600", "--out", j("hour.csv")])

        print("1. the physics twin")
        repeat(j("hour.csv"), j("day.csv"), 24)
        for label, csv in [("1 h", "hour.csv"), ("24 h", "day.csv")]:
            end, _, rss, wall = watch(tw, j("twin.ssp"), j(csv), j("a.jsonl"))
            results[f"physics {label}"] = describe(f"physics, {label}", end, rss, wall)
        os.remove(j("day.csv"))

        print(f"2. with the GP corrector learning online (budget {a.budget})")
        hours = max(1, a.corrector_hours)
        repeat(j("hour.csv"), j("long.csv"), hours)
        for label, csv in [("1 h", "hour.csv"), (f"{hours} h", "long.csv")]:
            end, _, rss, wall = watch(tw, j("corrected.ssp"), j(csv), j("a.jsonl"),
                                      ["--budget", str(a.budget)])
            results[f"corrector {label}"] = describe(f"corrector, {label}", end, rss, wall)

        print("3. the alert after a change (k2 stepped down at 30 s of a 60 s record)")
        latency = []
        for factor in ["0.85", "0.9", "0.95"]:
            csv = j(f"change-{factor}.csv")
            run([tw, "synth", "--seed", "3", "--duration", "60", "--change",
                 f"k2@30:{factor}", "--out", csv])
            end, alerts, _, _ = watch(tw, j("twin.ssp"), csv, j("a.jsonl"))
            failing = [x for x in alerts if x["kind"] == "failing" and x["time"] >= 30.0]
            early = [x for x in alerts if x["kind"] == "failing" and x["time"] < 30.0]
            if failing:
                delay = failing[0]["time"] - 30.0
                print(f"k2 x {factor}: failing alert at {failing[0]['time']:.3f} s, "
                      f"{delay:.3f} s after the change (window from {failing[0]['start']:.3f} s);"
                      f" per-sample latency p99 {end['latency_p99_us']:.2f} us;"
                      f" alerts before the change: {len(early)}")
            else:
                delay = None
                print(f"k2 x {factor}: no failing alert (stream NMSE % {end['nmse']}, "
                      f"tolerance {end['tolerance']:.3f} %); alerts before the change: "
                      f"{len(early)}")
            latency.append({"factor": float(factor), "delay_s": delay,
                            "alerts_before": len(early)})
        results["alert_latency"] = latency

    day, hour = results["physics 24 h"], results["physics 1 h"]
    print(f"\nmemory: 24 h / 1 h peak RSS = {day['peak_rss_mib'] / hour['peak_rss_mib']:.3f}"
          f" (physics); corrector {hours} h / 1 h = "
          f"{results[f'corrector {hours} h']['peak_rss_mib'] / results['corrector 1 h']['peak_rss_mib']:.3f}")
    slowest = min(r["real_time_factor"] for k, r in results.items() if k != "alert_latency")
    print(f"goal >= 100x real time on one core: {'met' if slowest >= 100 else 'NOT met'}"
          f" (slowest {slowest:,.0f}x)")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(results, f, indent=2)


if __name__ == "__main__":
    main()
