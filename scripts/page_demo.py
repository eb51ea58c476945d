"""The demo's live page: a record replayed into `twin watch --serve` at `--speed` times real time,
the page opened in a headless chromium (selenium, Debian's chromium-driver), and a screenshot
taken once the background diagnosis has landed on the page (or the stream has ended).

    .venv/bin/python scripts/page_demo.py --twin-bin target/release/twin --twin T.ssp \\
        --record data/dataset3.csv --out out/demo/page.png
"""

import argparse
import os
import re
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--twin-bin", required=True)
    p.add_argument("--twin", required=True)
    p.add_argument("--record", required=True)
    p.add_argument("--alerts", required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--speed", type=float, default=2.0)
    a = p.parse_args()
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    replay = subprocess.Popen([sys.executable, str(ROOT / "scripts/replay.py"), a.record, "--speed", str(a.speed)],
                              stdout=subprocess.PIPE)
    watch = subprocess.Popen([a.twin_bin, "watch", "--twin", a.twin, "--source", "-", "--alerts", a.alerts,
                              "--serve", "127.0.0.1:0", "--serve-linger", "300", "--token", "demo"],
                             stdin=replay.stdout, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    replay.stdout.close()
    driver = None
    try:
        line = watch.stderr.readline()
        m = re.fullmatch(r"serving (http://[\d.:]+/)\n", line)
        if not m:
            raise SystemExit(f"twin watch did not serve: {line!r}{watch.stderr.read()}")
        url = m.group(1)
        threading.Thread(target=watch.stderr.read, daemon=True).start()
        options = webdriver.ChromeOptions()
        options.binary_location = "/usr/bin/chromium"
        with tempfile.TemporaryDirectory() as profile:
            for f in ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                      "--disable-background-networking", "--disable-component-update", "--disable-sync",
                      "--disable-dev-shm-usage", "--window-size=1400,1050", "--hide-scrollbars",
                      f"--user-data-dir={profile}"]:
                options.add_argument(f)
            driver = webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=options)
            driver.get(url)
            deadline = time.monotonic() + 600
            landed = "return document.getElementById('diagnosis').dataset.action"
            ended = "return [...document.querySelectorAll('#alerts li')].some(l => l.dataset.kind === 'end')"
            while time.monotonic() < deadline:
                if driver.execute_script(landed) and driver.execute_script(ended):
                    break
                time.sleep(0.5)
            time.sleep(1.0)
            Path(a.out).parent.mkdir(parents=True, exist_ok=True)
            driver.save_screenshot(a.out)
            action = driver.execute_script(landed) or "none yet"
            driver.quit()
            driver = None
        print(f"page: {url} (the diagnosis on it: {action}); screenshot {a.out}")
    finally:
        if driver:
            driver.quit()
        watch.terminate()
        watch.wait()
        replay.wait()


if __name__ == "__main__":
    main()
