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
   `--runs` times, alternating, with a third condition between them: ten raw clients (nine
   threads reading the event stream and dropping it, one stalled socket), which costs the machine
   almost nothing, so it shows what the hub and the server cost the watch. Medians and their
   ratios, of the wall-clock speed and of the watch's own CPU time per sample: the browsers
   share the machine's two cores with the watch, so the wall-clock ratio includes their drawing,
   while the CPU ratio is the watch's own cost.

The same stream's sample read → event received, by a raw socket client without a browser, tells
the server's share of the latency from the browser's. The load average is printed beside: on a
shared machine the browser's frames wait for the cores.

Nothing here is asserted; the figures are printed (and written as JSON with --json).
"""

import argparse
import json
import os
import re
import resource
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request
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
        draw_ms = driver.execute_script("return window.twinPage.drawMs")
        arrivals = sorted(driver.execute_script("return window.twinPage.arrivals"))
    finally:
        driver.quit()
        watch.terminate()
        watch.wait()
    values.sort()
    draw_ms.sort()
    return {"points": len(values), "median_ms": statistics.median(values),
            "p99_ms": values[min(len(values) - 1, int(0.99 * len(values)))], "max_ms": values[-1],
            "draw_median_ms": statistics.median(draw_ms), "draw_p99_ms": draw_ms[int(0.99 * len(draw_ms))],
            "frames": len(draw_ms), "load": os.getloadavg()[0],
            "arrival_median_ms": statistics.median(arrivals), "arrival_p99_ms": arrivals[int(0.99 * len(arrivals))]}


def server_latency(args, env, work):
    """Sample read → event received, by a raw client reading the event stream (no browser)."""
    text = (work / "stream.csv").read_text().splitlines(keepends=True)
    watch, url = start_watch(args.twin_bin, str(work / "T.ssp"), str(work / "srv.jsonl"), env,
                             ["--no-diagnosis", "--serve", "127.0.0.1:0"])
    host, port = url[len("http://"):-1].split(":")
    s = socket.create_connection((host, int(port)))
    s.sendall(f"GET /events HTTP/1.1\r\nHost: {host}:{port}\r\n\r\n".encode())
    values = []

    def read():
        buffer = b""
        while True:
            data = s.recv(65536)
            if not data:
                return
            now = time.time() * 1e3
            buffer += data
            while b"\n\n" in buffer:
                event, buffer = buffer.split(b"\n\n", 1)
                for line in event.split(b"\n"):
                    if line.startswith(b"data: ") and b'"type":"point"' in line:
                        values.append(now - json.loads(line[6:])["wall"])
    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    time.sleep(0.5)
    watch.stdin.write(text[0])
    chunk = int(51.2 * 5 * 0.1)
    for k in range(1, len(text), chunk):
        watch.stdin.write("".join(text[k:k + chunk]))
        watch.stdin.flush()
        time.sleep(0.1)
    watch.stdin.close()
    watch.wait()
    reader.join(timeout=10)
    s.close()
    values.sort()
    return {"points": len(values), "median_ms": statistics.median(values),
            "p99_ms": values[int(0.99 * len(values))]}


def raw_readers(url, count):
    """`count` event streams read (and dropped) by threads: clients that cost the machine
    almost nothing, to tell the hub's cost from the browsers' CPU."""
    host, port = url[len("http://"):-1].split(":")
    socks = []
    for _ in range(count):
        s = socket.create_connection((host, int(port)))
        s.sendall(f"GET /events HTTP/1.1\r\nHost: {host}:{port}\r\n\r\n".encode())
        socks.append(s)

        def drain(s=s):
            try:
                while s.recv(65536):
                    pass
            except OSError:
                pass
        threading.Thread(target=drain, daemon=True).start()
    return socks


def speed_once(args, env, work, pages, browsers=True, serve=False):
    stream = (work / "fast.csv").read_bytes()
    extra = ["--no-diagnosis"]
    if pages or serve:
        extra += ["--serve", "127.0.0.1:0"]
    alerts = work / f"speed-{pages}.jsonl"
    watch, url = start_watch(args.twin_bin, str(work / "T.ssp"), str(alerts), env, extra)
    drivers, stalled = [], None
    try:
        readers = []
        if pages and not browsers:
            readers = raw_readers(url, pages - 1)
        if pages and browsers:
            # Three pages a browser: over HTTP/1.1 a browser keeps six connections to a host, and
            # each page holds one for its event stream.
            for k in range(0, pages - 1, 3):
                driver = browser(work / f"chrome-speed-{k}")
                drivers.append(driver)
                driver.get(url)
                for _ in range(min(3, pages - 1 - k) - 1):
                    driver.switch_to.new_window("window")
                    driver.get(url)
        if pages:
            host, port = url[len("http://"):-1].split(":")
            stalled = socket.create_connection((host, int(port)))
            stalled.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
            stalled.sendall(f"GET /events HTTP/1.1\r\nHost: {host}:{port}\r\n\r\n".encode())
            if not browsers:
                wait(lambda: json.loads(urllib.request.urlopen(url + "api/stats", timeout=10).read())["clients"] >= pages)
            for driver in drivers:
                for handle in driver.window_handles:
                    driver.switch_to.window(handle)
                    wait(lambda: driver.execute_script("return window.twinPage && window.twinPage.live()"))
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        watch.stdin.buffer.write(stream)
        watch.stdin.close()
        watch.wait(timeout=600)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    finally:
        for d in drivers:
            d.quit()
        if stalled:
            stalled.close()
        for r in readers:
            r.close()
        if watch.poll() is None:
            watch.terminate()
            watch.wait()
    end = end_alert(alerts)
    # The watch's own CPU time per sample (the only child reaped while it ran): what it spends,
    # whatever the browsers take from the cores.
    return end["samples_per_second"], end["samples"] / cpu


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
        result = {"server_latency": server_latency(args, env, work)}
        srv = result["server_latency"]
        print(f"latency sample read → event received (raw client, no browser): median {srv['median_ms']:.2f} ms, "
              f"p99 {srv['p99_ms']:.2f} ms ({srv['points']} points)", flush=True)
        result["latency"] = latency(args, env, work)
        lat = result["latency"]
        print(f"latency sample read → point drawn: median {lat['median_ms']:.1f} ms, p99 {lat['p99_ms']:.1f} ms "
              f"(max {lat['max_ms']:.1f} ms; {lat['points']} points, one page, 5× real time); in the page's JavaScript "
              f"median {lat['arrival_median_ms']:.1f} ms, p99 {lat['arrival_p99_ms']:.1f} ms; a frame's drawing "
              f"median {lat['draw_median_ms']:.1f} ms, p99 {lat['draw_p99_ms']:.1f} ms over {lat['frames']} frames; "
              f"load average {lat['load']:.1f}", flush=True)
        runs = {"no page": [], "served, no client": [], "ten raw clients, one stalled": [],
                "ten pages, one stalled": []}
        for _ in range(args.runs):
            runs["no page"].append(speed_once(args, env, work, 0))
            runs["served, no client"].append(speed_once(args, env, work, 0, serve=True))
            runs["ten raw clients, one stalled"].append(speed_once(args, env, work, 10, browsers=False))
            runs["ten pages, one stalled"].append(speed_once(args, env, work, 10))
            print("  " + "; ".join(f"{k}: {v[-1][0]:.0f} samples/s, {v[-1][1]:.0f} per CPU s"
                                   for k, v in runs.items()), flush=True)
        base_wall = statistics.median(r[0] for r in runs["no page"])
        base_cpu = statistics.median(r[1] for r in runs["no page"])
        result["speed"] = {}
        print("watch speed (120 000 samples at 1 kHz, --no-diagnosis), medians:")
        for k, v in runs.items():
            wall = statistics.median(r[0] for r in v)
            cpu = statistics.median(r[1] for r in v)
            result["speed"][k] = {"runs": v, "samples_per_second": wall, "samples_per_cpu_second": cpu,
                                  "ratio_wall": wall / base_wall, "ratio_cpu": cpu / base_cpu}
            print(f"  {k}: {wall:.0f} samples/s (×{wall / base_wall:.2f}), "
                  f"{cpu:.0f} samples per CPU second of the watch (×{cpu / base_cpu:.2f})")
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    sys.exit(main())
