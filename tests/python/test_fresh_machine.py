"""The demo on a fresh machine: what it needs from the machine is checked (and, as root with
apt-get, installed) before anything is built, so a machine without chromium stops the demo in its
first seconds with the packages to install — not after twenty minutes at the live page's
screenshot. The demo itself is too long for the test command; this runs its first step on a PATH
without chromium and chromedriver, with SHEAR_TWIN_NO_INSTALL=1 so it reports instead of
installing. As root on a machine with apt-get, the same first step installs the two packages
and the demo goes on: shown on that PATH with an `apt-get` (and an `id`) of the test's own.
"""

import os
import shutil
import subprocess
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
MISSING = ("chromium", "chromedriver")


def path_without(tmp_path, names):
    """A PATH of one directory: every program the real PATH finds, but the named ones."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    for d in os.environ["PATH"].split(os.pathsep):
        if not os.path.isdir(d):
            continue
        for entry in os.scandir(d):
            if entry.name in names or (bin_dir / entry.name).exists():
                continue
            if entry.is_file() and os.access(entry.path, os.X_OK):
                (bin_dir / entry.name).symlink_to(entry.path)
    for name in names:
        assert not (bin_dir / name).exists()
    return str(bin_dir)


def test_demo_stops_at_once_naming_what_to_install(tmp_path):
    env = dict(os.environ, PATH=path_without(tmp_path, MISSING), SHEAR_TWIN_NO_INSTALL="1")
    start = time.monotonic()
    run = subprocess.run([str(ROOT / "scripts/demo.sh")], cwd=ROOT, env=env, capture_output=True,
                         text=True, timeout=120)
    seconds = time.monotonic() - start
    assert run.returncode != 0, run.stdout
    assert "missing: chromium chromium-driver" in run.stderr, run.stderr
    assert "apt-get install -y chromium chromium-driver" in run.stderr, run.stderr
    # Nothing was built or installed before the stop: the first section is the only one.
    assert "set-up 1/4" in run.stdout and "set-up 2/4" not in run.stdout, run.stdout
    assert "the demo stopped" in run.stdout, run.stdout
    # Seconds, not the minutes a build would take (measured: well under 1 s; a shared machine).
    assert seconds < 30, seconds


def test_the_demo_prerequisites_hold_on_the_test_machine():
    # The test command installed them (scripts/prerequisites.sh): the demo's check passes.
    if shutil.which("chromium") is None:
        raise AssertionError("scripts/test.sh's prerequisites step should have installed chromium")
    run = subprocess.run([str(ROOT / "scripts/prerequisites.sh"), "--demo", "--check"], cwd=ROOT,
                         capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stderr


FAKE_APT_GET = """#!/bin/sh
echo "$@" >> "{log}"
if [ "$1" = install ]; then
  for name in chromium chromedriver; do
    printf '#!/bin/sh\\nexit 0\\n' > "{bin}/$name"
    chmod +x "{bin}/$name"
  done
fi
"""


def test_the_demos_first_step_installs_chromium_as_root_with_apt_get(tmp_path):
    """`scripts/prerequisites.sh --demo` (the demo's first step) on a PATH without chromium,
    chromedriver and apt-get, as root (a stand-in `id -u` says 0) with a stand-in `apt-get` that
    logs its arguments and puts the two programs on that PATH as `apt-get install` would: it
    installs exactly the two Debian packages, checks them again and exits 0, so the demo goes on
    to its next section instead of stopping."""
    bin_dir = path_without(tmp_path, MISSING + ("apt-get", "id"))
    log = tmp_path / "apt-get.log"
    (Path(bin_dir) / "apt-get").write_text(FAKE_APT_GET.format(log=log, bin=bin_dir))
    (Path(bin_dir) / "id").write_text("#!/bin/sh\necho 0\n")
    for name in ("apt-get", "id"):
        (Path(bin_dir) / name).chmod(0o755)
    env = dict(os.environ, PATH=bin_dir)
    env.pop("SHEAR_TWIN_NO_INSTALL", None)
    run = subprocess.run([str(ROOT / "scripts/prerequisites.sh"), "--demo"], cwd=ROOT, env=env,
                         capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stderr
    assert "installing chromium chromium-driver" in run.stderr, run.stderr
    assert log.read_text().splitlines() == ["update -qq", "install -y -qq chromium chromium-driver"]
    for name in MISSING:
        assert (Path(bin_dir) / name).is_file(), name
