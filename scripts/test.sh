#!/usr/bin/env bash
# The test command: the machine's prerequisites (checked in seconds; as root with apt-get the
# missing Debian packages are installed, otherwise it stops with the command to run), the
# Python venv with fmpy and the third-party tools, the FMUs, the shear_twin package (built from
# python/ with maturin into .venv), both installs used from outside the repository
# (scripts/test-installs.sh), then every Rust test of the workspace and the Python tests; the
# book (docs/, scripts/book.sh: built and its links checked) beside the venv's set-up.
#
# Where the time goes is kept busy on every core: the venv is made (pip, mostly waiting on files
# and the network) while the FMUs and `twin` compile; the Rust tests run with cargo-nextest when
# it is installed (each test its own process, the tests of all binaries sharing the cores, so one
# long test no longer holds the rest back; else `cargo test`), and the Python tests run beside
# them. Each phase's wall time is printed at the end.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"

phases=()
phase() { # phase NAME COMMAND...: run it, note its wall time, return its status
  local name=$1 start=$SECONDS status=0
  shift
  "$@" || status=$?
  phases+=("$name: $((SECONDS - start)) s")
  return "$status"
}

phase prerequisites scripts/prerequisites.sh
# The library's import graph against its layers (ARCHITECTURE.md, "Layers"): a fraction of a second.
phase "import graph" scripts/import-graph.py >/dev/null

start=$SECONDS
python_log=$(mktemp "${TMPDIR:-/tmp}/shear-twin-setup-python.XXXXXX")
scripts/setup-python.sh >"$python_log" 2>&1 &
setup_python=$!
# The book (scripts/book.sh: mdbook into target/tools once, the build, the link check) beside
# the venv; its phase line goes through a file, the subshell's phases being its own.
book_log=$(mktemp "${TMPDIR:-/tmp}/shear-twin-book.XXXXXX")
(
  book_status=0
  phase "book" scripts/book.sh || book_status=$?
  printf '%s\n' "${phases[-1]}" >"$book_log.phase"
  exit "$book_status"
) >"$book_log" 2>&1 &
book=$!
phase "FMUs and twin (release; the venv beside it)" scripts/build-fmus.sh
status=0
wait "$setup_python" || status=$?
cat "$python_log" >&2
rm -f "$python_log"
[ "$status" -eq 0 ] || { echo "test.sh: scripts/setup-python.sh failed" >&2; exit "$status"; }
phases+=("venv and FMUs together: $((SECONDS - start)) s")
book_status=0
wait "$book" || book_status=$?
echo "--- scripts/book.sh" >&2
cat "$book_log" >&2
phases+=("$(cat "$book_log.phase" 2>/dev/null || echo "book: did not finish") (beside the venv and FMUs)")
rm -f "$book_log" "$book_log.phase"
[ "$book_status" -eq 0 ] || { echo "test.sh: scripts/book.sh failed" >&2; exit "$book_status"; }

phase "third-party FMUs" scripts/make-third-party-fmus.sh
phase "C FMUs" scripts/make-c-fmus.sh
phase "Python package" scripts/install-python-package.sh
phase "installs" scripts/test-installs.sh

# The Rust tests' build, then the Rust and the Python tests side by side. The tests build in
# the release profile: the dependencies are the ones `twin` was just built with (the dev
# profile compiled them all a second time, 508 s of a 39-minute run), and the tests that drive
# `twin` and the diagnosis run its optimised code (the hybrid test's contact law: 220 s in the
# dev profile, 22 s in release).
if cargo nextest --version >/dev/null 2>&1; then
  phase "Rust tests build" cargo nextest run --workspace --release --no-run
  rust_tests=(cargo nextest run --workspace --release --no-fail-fast)
else
  phase "Rust tests build" cargo test --workspace --release --no-run
  rust_tests=(cargo test --workspace --release --no-fail-fast)
fi
start=$SECONDS
pytest_log=$(mktemp "${TMPDIR:-/tmp}/shear-twin-pytest.XXXXXX")
.venv/bin/python -m pytest tests/python -q --durations=15 >"$pytest_log" 2>&1 &
pytest=$!
rust_status=0
"${rust_tests[@]}" || rust_status=$?
phases+=("Rust tests (the Python tests beside them): $((SECONDS - start)) s")
python_status=0
wait "$pytest" || python_status=$?
phases+=("Python tests (beside the Rust tests): $((SECONDS - start)) s")
echo "--- pytest tests/python -q" >&2
cat "$pytest_log" >&2
rm -f "$pytest_log"
# nextest runs no doc-tests: they run here (cargo test ran them with the rest).
doc_status=0
if [ "${rust_tests[1]}" = nextest ]; then
  phase "doc-tests" cargo test --workspace --release --doc || doc_status=$?
fi

printf '  %s\n' "${phases[@]}" >&2
[ "$rust_status" -eq 0 ] || { echo "test.sh: Rust tests failed" >&2; exit "$rust_status"; }
[ "$doc_status" -eq 0 ] || { echo "test.sh: doc-tests failed" >&2; exit "$doc_status"; }
[ "$python_status" -eq 0 ] || { echo "test.sh: Python tests failed" >&2; exit "$python_status"; }
