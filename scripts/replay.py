"""Replay a record (CSV, `time` first) on standard output as a live stream: the header, then each
line when its time has come, at `--speed` times real time. For `twin watch --source -`:

    python3 scripts/replay.py data/dataset3.csv --speed 2 | twin watch --twin T.ssp --source - \\
        --alerts alerts.jsonl --serve 127.0.0.1:8080
"""

import argparse
import sys
import time


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("record")
    p.add_argument("--speed", type=float, default=1.0, help="times real time (default 1)")
    p.add_argument("--repeat", type=int, default=1, help="play it this many times, times shifted on")
    a = p.parse_args()
    with open(a.record) as f:
        header, *lines = f.read().splitlines()
    rows = [(float(line.split(",", 1)[0]), line.split(",", 1)[1]) for line in lines if line.strip()]
    span = rows[-1][0] - rows[0][0] + (rows[1][0] - rows[0][0] if len(rows) > 1 else 0.0)
    out = sys.stdout
    out.write(header + "\n")
    out.flush()
    started = time.monotonic()
    t0 = rows[0][0]
    try:
        for r in range(a.repeat):
            for t, rest in rows:
                t = t + r * span
                due = started + (t - t0) / a.speed
                wait = due - time.monotonic()
                if wait > 0.005:
                    out.flush()
                    time.sleep(wait)
                out.write(f"{t:.6f},{rest}\n")
        out.flush()
    except BrokenPipeError:
        pass


if __name__ == "__main__":
    main()
