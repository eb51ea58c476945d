#!/usr/bin/env python3
"""The sizes issue 39 tracks: Rust files over 1,000 lines and functions over 100 / 150 / 200
lines, in the files git tracks.

    scripts/code-sizes.py            # the counts, then the lists
    scripts/code-sizes.py --counts   # the counts alone

A file counts whole (its unit tests included). A function is counted from its `fn` line to the
line of its closing brace, found by counting braces outside comments, strings and character
literals; functions inside a `#[cfg(test)]` module, in a unit-test file `tests.rs` and in `tests/`,
`benches/` and `examples/` folders are reported apart ("test") from the rest ("production"), and
so are files there.
"""

import re
import subprocess
import sys

FN = re.compile(r"^\s*(pub(\([^)]*\))?\s+)?((const|async|unsafe|extern\s+\"C\")\s+)*fn\s+(\w+)")
TEST_DIRS = ("tests/", "benches/", "examples/")


def code_of(line, state):
    """The line with comments, strings and character literals blanked; `state` carries an open
    block comment or string across lines."""
    out = []
    i = 0
    while i < len(line):
        c = line[i]
        if state["block"]:
            if line.startswith("*/", i):
                state["block"] -= 1
                i += 2
            elif line.startswith("/*", i):
                state["block"] += 1
                i += 2
            else:
                i += 1
            continue
        if state["string"] is not None:
            end = state["string"]
            if end == '"' and c == "\\":
                i += 2
                continue
            if line.startswith(end, i):
                state["string"] = None
                i += len(end)
            else:
                i += 1
            continue
        if line.startswith("//", i):
            break
        if line.startswith("/*", i):
            state["block"] = 1
            i += 2
            continue
        raw = re.match(r'b?r(#*)"', line[i:])
        if raw and (i == 0 or not (line[i - 1].isalnum() or line[i - 1] == "_")):
            state["string"] = '"' + raw.group(1)
            i += raw.end()
            continue
        if c == '"':
            state["string"] = '"'
            i += 1
            continue
        char = re.match(r"'(\\.|\\u\{[0-9a-fA-F]+\}|[^\\'])'", line[i:])
        if char:
            i += char.end()
            continue
        out.append(c)
        i += 1
    return "".join(out)


def functions(path):
    """(name, first line, lines, in a test module) of each function of a file."""
    lines = open(path, encoding="utf-8").read().split("\n")
    state = {"block": 0, "string": None}
    depth = 0
    nest = 0  # open ( and [
    open_fns = []  # (name, start, depth at its body, test)
    test_depths = []  # depths of open #[cfg(test)] modules
    pending_test = False
    found = []
    for number, line in enumerate(lines, 1):
        code = code_of(line, state)
        stripped = code.strip()
        if stripped.startswith("#[cfg(test)]"):
            pending_test = True
        m = FN.match(code)
        if m:
            open_fns.append([m.group(5), number, None, bool(test_depths)])
        if pending_test and re.match(r"^\s*(pub\s+)?mod\s+\w+\s*\{", code):
            test_depths.append(depth + 1)
            pending_test = False
        elif pending_test and stripped and not stripped.startswith("#"):
            pending_test = False
        for c in code:
            if c in "([":
                nest += 1
            elif c in ")]":
                nest -= 1
            elif c == "{":
                depth += 1
                for f in open_fns:
                    if f[2] is None:
                        f[2] = depth
            elif c == "}":
                for f in list(open_fns):
                    if f[2] == depth:
                        found.append((f[0], f[1], number - f[1] + 1, f[3]))
                        open_fns.remove(f)
                if test_depths and test_depths[-1] == depth:
                    test_depths.pop()
                depth -= 1
            elif c == ";" and nest == 0:
                # A declaration without a body (a trait's required method).
                open_fns = [f for f in open_fns if f[2] is not None]
    return found


def main():
    files = subprocess.run(
        ["git", "ls-files", "*.rs"], capture_output=True, text=True, check=True
    ).stdout.split()
    big = []
    long = []
    for path in files:
        n = sum(1 for _ in open(path, encoding="utf-8"))
        in_tests = (
            any(part in path for part in TEST_DIRS)
            or path.startswith(TEST_DIRS)
            or path.endswith("/tests.rs")
        )
        if n > 1000:
            big.append((n, path, "test" if in_tests else "production"))
        for name, start, size, test_module in functions(path):
            kind = "test" if in_tests or test_module else "production"
            if size > 100:
                long.append((size, f"{path}:{start} {name}", kind))
    print("files over 1,000 lines:", len(big),
          f"({sum(1 for b in big if b[2] == 'production')} production)")
    for limit in (100, 150, 200):
        over = [f for f in long if f[0] > limit]
        print(f"functions over {limit} lines: {len(over)}",
              f"({sum(1 for f in over if f[2] == 'production')} production)")
    if "--counts" in sys.argv:
        return
    print("\nfiles over 1,000 lines:")
    for n, path, kind in sorted(big, reverse=True):
        print(f"  {n:5} {kind:10} {path}")
    print("\nfunctions over 100 lines:")
    for size, where, kind in sorted(long, reverse=True):
        print(f"  {size:5} {kind:10} {where}")


if __name__ == "__main__":
    main()
