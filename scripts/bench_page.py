"""The live page's cost: latency from a sample read to its point drawn, and the watch's speed
with and without pages open. Driven by scripts/bench-page.sh, which builds `twin` and the FMUs
and passes their paths. Uses .venv's selenium and Debian's chromium (headless).

1. Latency. A twin calibrated on a 20 s synthetic record (seed 1) watches a 60 s record (seed 2)
   piped in at 5× real time (chunks every 0.1 s) with one page open. The server stamps each
   point with the wall time the watcher read its sample; the page records
   performance.timeOrigin + performance.now() in the animation frame that draws it. The
   difference per point: median and p99 (same machine, same clock).
2. Speed. The same twin on a 120 s record sampled at 1 kHz (120 000 samples), written into the
   watch's standard input as fast as the pipe takes it, `--no-diagnosis`: samples per second
   from the `end` alert, with no page open, then with ten pages open — nine headless chromium
   windows (three browsers of three) and one raw socket that sends GET /events and never reads. Each condition is run
   `--runs` times, alternating; medians and their ratio. The pages and the watch share the
   machine's cores: the ratio includes the browsers' own CPU use, not only the hub's.

Nothing here is asserted; the figures are printed (and written as JSON with --json).
"""

import argparse
import json
import os
import re
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-dev-shm-usage", "--window-size=1200,900"]


def run(cmd, env):
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, env=env)


def browser(user_dir):
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    options = webdriver.ChromeOptions()
    options.binary_location = "/usr/bin/chromium"
    for f in FLAGS + [f"--user-data-dir={user_dir}"]:
        options.add_argument(f)
    return webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=options)


def start_watch(twin_bin, twin, alerts, env, extra=()):
    watch = subprocess.Popen(
        [twin_bin, "watch", "--twin", twin, "--source", "-", "--alerts", alerts, *extra],
        stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env)
    url = None
    if "--serve" in extra:
        line = watch.stderr.readline()
        m = re.fullmatch(r"serving (http://[\d.:]+/)\n", line)
        if not m:
            raise SystemExit(f"no serving line: {line!r}")
        url = m.group(1)
    threading.Thread(target=lambda: watch.stderr.read(), daemon=True).start()
    return watch, url


def end_alert(alerts):
    for line in reversed(Path(alerts).read_text().splitlines()):
        a = json.loads(line)
        if a["kind"] == "end":
            return a
    raise SystemExit(f"{alerts}: no end alert")


def wait(check, limit=120):
    deadline = time.monotonic() + limit
    while time.monotonic() < deadline:
        v = check()
        if v:
            return v
        time.sleep(0.1)
    raise SystemExit("timed out")


def latency(args, env, work):
    text = (work / "stream.csv").read_text().splitlines(keepends=True)
    watch, url = start_watch(args.twin_bin, str(work / "T.ssp"), str(work / "lat.jsonl"), env,
                             ["--no-diagnosis", "--serve", "127.0.0.1:0", "--serve-linger", "30"])
    driver = browser(work / "chrome-latency")
    try:
        driver.get(url)
        wait(lambda: driver.execute_script("return window.twinPage && window.twinPage.live()"))
        watch.stdin.write(text[0])
        chunk = int(51.2 * 5 * 0.1)  # 5× real time, a chunk every 0.1 s
        for k in range(1, len(text), chunk):
            watch.stdin.write("".join(text[k:k + chunk]))
            watch.stdin.flush()
            time.sleep(0.1)
        watch.stdin.close()
        wait(lambda: driver.execute_script(
            "return [...document.querySelectorAll('#alerts li')].some(l => l.dataset.kind === 'end')"))
        time.sleep(1.0)
        values = driver.execute_script("return window.twinPage.latencies")
    finally:
        driver.quit()
        watch.terminate()
        watch.wait()
    values.sort()
    return {"points": len(values), "median_ms": statistics.median(values),
            "p99_ms": values[min(len(values) - 1, int(0.99 * len(values)))], "max_ms": values[-1]}


def speed_once(args, env, work, pages):
    stream = (work / "fast.csv").read_bytes()
    extra = ["--no-diagnosis"]
    if pages:
        extra += ["--serve", "127.0.0.1:0"]
    alerts = work / f"speed-{pages}.jsonl"
    watch, url = start_watch(args.twin_bin, str(work / "T.ssp"), str(alerts), env, extra)
    drivers, stalled = [], None
    try:
        if pages:
            # Three pages a browser: over HTTP/1.1 a browser keeps six connections to a host, and
            # each page holds one for its event stream.
            for k in range(0, pages - 1, 3):
                driver = browser(work / f"chrome-speed-{k}")
                drivers.append(driver)
                driver.get(url)
                for _ in range(min(3, pages - 1 - k) - 1):
                    driver.switch_to.new_window("window")
                    driver.get(url)
            host, port = url[len("http://"):-1].split(":")
            stalled = socket.create_connection((host, int(port)))
            stalled.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
            stalled.sendall(f"GET /events HTTP/1.1\r\nHost: {host}:{port}\r\n\r\n".encode())
            for driver in drivers:
                for handle in driver.window_handles:
                    driver.switch_to.window(handle)
                    wait(lambda: driver.execute_script("return window.twinPage && window.twinPage.live()"))
        watch.stdin.buffer.write(stream) if hasattr(watch.stdin, "buffer") else watch.stdin.write(stream.decode())
        watch.stdin.close()
        watch.wait(timeout=600)
    finally:
        for d in drivers:
            d.quit()
        if stalled:
            stalled.close()
        if watch.poll() is None:
            watch.terminate()
            watch.wait()
    end = end_alert(alerts)
    return end["samples_per_second"]


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--twin-bin", required=True)
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--json")
    args = p.parse_args()
    env = dict(os.environ)
    with tempfile.TemporaryDirectory() as d:
        work = Path(d)
        t = args.twin_bin
        run([t, "synth", "--seed", "1", "--noise-sd", "0.003", "--duration", "20", "--out", str(work / "cal.csv")], env)
        run([t, "calibrate", "--data", str(work / "cal.csv"), "--out", str(work / "T.ssp")], env)
        run([t, "synth", "--seed", "2", "--noise-sd", "0.003", "--duration", "60", "--change", "k2@30:0.85",
             "--out", str(work / "stream.csv")], env)
        run([t, "synth", "--seed", "3", "--noise-sd", "0.003", "--duration", "120", "--sample-rate", "1000",
             "--out", str(work / "fast.csv")], env)
        result = {"latency": latency(args, env, work)}
        lat = result["latency"]
        print(f"latency sample read → point drawn: median {lat['median_ms']:.1f} ms, p99 {lat['p99_ms']:.1f} ms "
              f"(max {lat['max_ms']:.1f} ms; {lat['points']} points, one page, 5× real time)", flush=True)
        alone, with_pages = [], []
        for _ in range(args.runs):
            alone.append(speed_once(args, env, work, 0))
            with_pages.append(speed_once(args, env, work, 10))
            print(f"  samples/s: no page {alone[-1]:.0f}, ten pages (one stalled) {with_pages[-1]:.0f}", flush=True)
        a, w = statistics.median(alone), statistics.median(with_pages)
        result["speed"] = {"no_page": alone, "ten_pages": with_pages, "median_no_page": a,
                           "median_ten_pages": w, "ratio": w / a}
        print(f"watch speed (120 000 samples at 1 kHz, --no-diagnosis): no page {a:.0f} samples/s, "
              f"ten pages one stalled {w:.0f} samples/s; ratio {w / a:.2f}")
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    sys.exit(main())
