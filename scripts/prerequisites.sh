#!/usr/bin/env bash
# What the tests need from the machine, checked in the first seconds — before anything compiles.
#
#   scripts/prerequisites.sh          # check; as root with apt-get, install what is missing
#   scripts/prerequisites.sh --check  # check only, never install
#   scripts/prerequisites.sh --demo   # only what scripts/demo.sh needs (no libclang, no mosquitto)
#
# SHEAR_TWIN_NO_INSTALL=1 makes it check only, as --check does (tests/python/test_fresh_machine.py
# uses it to show that the demo stops at once, naming the packages, on a machine without them).
#
# Needed: cargo (Rust), CPython ≥ 3.10, a C compiler (the importer's logger shim, the C test
# FMUs), libclang (bindgen, for fmi-sys: the compile-time check of the exported C signatures
# and the independent rust-fmi importer test), mosquitto (the MQTT broker `twin watch`'s tests
# start on a loopback port), chromium and chromium-driver (the headless browser the live page's
# test, tests/python/test_page.py, drives through selenium). Rust and Python are not installed here:
# they come with the machine. The Debian packages are installed when this runs as root on a
# machine with apt-get; otherwise it stops at once with the command to run.
set -euo pipefail

check_only=false
demo_only=false
for arg in "$@"; do
  case "$arg" in
    --check) check_only=true ;;
    --demo) demo_only=true ;;
    *) echo "prerequisites: unknown option '$arg' (use --check, --demo)" >&2; exit 2 ;;
  esac
done
[ -n "${SHEAR_TWIN_NO_INSTALL:-}" ] && check_only=true

die() {
  echo "prerequisites: $*" >&2
  exit 1
}

command -v cargo >/dev/null 2>&1 ||
  die "cargo is not on PATH: install Rust (https://rustup.rs: curl --proto '=https' --tlsv1.2 -sSf https://sh.rustup.rs | sh)"

python=${PYTHON:-python3}
"$python" -c 'import sys; sys.exit(sys.version_info < (3, 10))' 2>/dev/null ||
  die "'$python' is missing or older than 3.10: install CPython 3.11 (Debian: apt-get install python3 python3-venv) or set PYTHON"

# libclang as clang-sys finds it: LIBCLANG_PATH, or a libclang.so the dynamic loader knows,
# or Debian's llvm directories.
have_libclang() {
  if [ -n "${LIBCLANG_PATH:-}" ]; then
    compgen -G "$LIBCLANG_PATH/libclang*.so*" >/dev/null && return 0
  fi
  ldconfig -p 2>/dev/null | grep -Eq 'libclang(-[0-9.]+)?\.so ' && return 0
  compgen -G "/usr/lib/llvm-*/lib/libclang.so" >/dev/null && return 0
  return 1
}

packages=()
command -v cc >/dev/null 2>&1 || packages+=(gcc)
have_mosquitto() {
  command -v mosquitto >/dev/null 2>&1 || [ -x /usr/sbin/mosquitto ]
}
if ! $demo_only; then
  have_libclang || packages+=(libclang-dev)
  have_mosquitto || packages+=(mosquitto)
fi
command -v chromium >/dev/null 2>&1 || packages+=(chromium)
command -v chromedriver >/dev/null 2>&1 || packages+=(chromium-driver)

[ ${#packages[@]} -eq 0 ] && exit 0

command="apt-get install -y ${packages[*]}"
if $check_only; then
  die "missing: ${packages[*]}; run: sudo $command"
fi
if [ "$(id -u)" -ne 0 ] || ! command -v apt-get >/dev/null 2>&1; then
  die "missing: ${packages[*]}; run: sudo apt-get update && sudo $command (then run this again)"
fi
echo "prerequisites: installing ${packages[*]}" >&2
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq || die "apt-get update failed; run: apt-get update && $command"
apt-get install -y -qq "${packages[@]}" >/dev/null || die "'$command' failed"
$demo_only || have_libclang || die "libclang-dev is installed but no libclang.so is found; set LIBCLANG_PATH"
$demo_only || have_mosquitto || die "mosquitto is installed but not found in PATH or /usr/sbin"
command -v chromium >/dev/null 2>&1 || die "chromium is installed but not found in PATH"
command -v chromedriver >/dev/null 2>&1 || die "chromium-driver is installed but chromedriver is not in PATH"
