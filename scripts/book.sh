#!/usr/bin/env bash
# The book (docs/, mdBook): installs mdbook into target/tools when it is missing (a pinned
# version, built from crates.io once, unoptimised, and kept in target/), builds the book into
# target/book, and checks every relative link and #anchor of docs/src/**/*.md and README.md
# (scripts/check_links.py). Exits non-zero on any failure; prints each step's time.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"

version=0.4.52
tools="$root/target/tools"
mdbook="$tools/bin/mdbook"
start=$SECONDS
if [ ! -x "$mdbook" ] || [ "$("$mdbook" --version 2>/dev/null)" != "mdbook v$version" ]; then
  echo "book.sh: installing mdbook $version into target/tools (once; a few minutes)" >&2
  # The dev profile without debug information: the book builds in a second either way, and
  # compiling mdbook unoptimised takes a fraction of the release build's CPU, which
  # scripts/test.sh spends beside the FMUs' build.
  CARGO_PROFILE_DEV_DEBUG=0 cargo install --debug --locked mdbook --version "$version" \
    --no-default-features --root "$tools"
fi
installed=$SECONDS
"$mdbook" build docs --dest-dir "$root/target/book"
built=$SECONDS
python3 scripts/check_links.py "$root"
echo "book.sh: mdbook $((installed - start)) s, build $((built - installed)) s, links $((SECONDS - built)) s; the book is target/book/index.html" >&2
