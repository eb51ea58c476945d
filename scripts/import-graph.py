#!/usr/bin/env python3
"""The orchestrator library's import graph, checked against its layers.

Reads orchestrator/src (the library: not main.rs nor commands/, which are the binary's; not the
test modules) and collects every `crate::…` and `super::…` path. It prints the edges between the
top-level modules and between the workflows, and fails (exit 1) when

- a top-level module imports one in its own or a higher layer (LAYERS, bottom first), or
- the workflows (workflows/<name>) import each other in a circle.

Circles among the files of one module (e.g. a type whose methods are spread over files) are
listed with --files, not failed.

    scripts/import-graph.py [--files]
"""

import os
import re
import sys
from collections import defaultdict

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "orchestrator", "src")

# Bottom first; a module may import only from the layers below its own.
LAYERS = [
    ["fsutil", "parallel", "choice"],
    ["record"],
    ["cosim", "evaluation"],
    ["twin", "blocks", "synth"],
    ["workflows"],
    ["report"],
    ["serve"],
]
LAYER = {module: i for i, layer in enumerate(LAYERS) for module in layer}


def library_files():
    """(module path as a list, text without comments and test modules) of each library file."""
    for folder, _, files in os.walk(ROOT):
        for name in sorted(files):
            if not name.endswith(".rs"):
                continue
            rel = os.path.relpath(os.path.join(folder, name), ROOT).replace(os.sep, "/")
            if rel in ("lib.rs", "main.rs") or rel.startswith("commands/"):
                continue
            parts = rel[: -len(".rs")].split("/")
            if parts[-1] == "tests" or "tests" in parts[:-1]:
                continue
            if parts[-1] == "mod":
                parts = parts[:-1]
            with open(os.path.join(folder, name), encoding="utf-8") as f:
                text = f.read()
            cut = re.search(r"#\[cfg\(test\)\]\s*mod tests\b", text)
            if cut:
                text = text[: cut.start()]
            yield parts, re.sub(r"//[^\n]*", "", text)


def braced(text, start):
    """The text inside the braces opening at `start`, and the index after them."""
    depth = 0
    for i in range(start, len(text)):
        depth += {"{": 1, "}": -1}.get(text[i], 0)
        if depth == 0:
            return text[start + 1 : i], i + 1
    return text[start + 1 :], len(text)


def heads(group):
    """The first two names of each path in a `{a::b, c::{d, e}}` group."""
    parts, depth, current = [], 0, ""
    for ch in group:
        depth += {"{": 1, "}": -1}.get(ch, 0)
        if ch == "," and depth == 0:
            parts.append(current)
            current = ""
        else:
            current += ch
    parts.append(current)
    for part in parts:
        names = re.findall(r"[A-Za-z_][A-Za-z0-9_]*", part)
        if names and names[0] != "self":
            yield names[0], names[1] if len(names) > 1 else None


def targets(parts, text):
    """The module paths (lists) a file's `crate::` and `super::` paths name."""
    for m in re.finditer(r"\bcrate::", text):
        rest = text[m.end() :]
        if rest.startswith("{"):
            group, _ = braced(text, m.end())
            for first, second in heads(group):
                yield [first] + ([second] if second else [])
        else:
            yield re.findall(r"[A-Za-z_][A-Za-z0-9_]*", rest[:200])[:2]
    for m in re.finditer(r"\b((?:super::)+)([a-z_][a-z0-9_]*)", text):
        ups = m.group(1).count("super::")
        yield parts[: len(parts) - ups] + [m.group(2)]


def edges(depth):
    """{source: {target: files}} between module paths cut to `depth` names."""
    graph = defaultdict(lambda: defaultdict(set))
    for parts, text in library_files():
        source = "/".join(parts[:depth])
        for target in targets(parts, text):
            # A lower-case second name is a module; an upper-case one an item of the first.
            target = [t for i, t in enumerate(target) if i == 0 or t[:1].islower()]
            name = "/".join(target[:depth])
            if name and name != source and not source.startswith(name + "/"):
                graph[source][name].add("/".join(parts))
    return graph


def circles(graph):
    """The strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, {}):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def main():
    sys.setrecursionlimit(10000)
    failures = []
    top = edges(1)
    print("top-level modules (layers, bottom first: "
          + " < ".join("{" + ", ".join(layer) + "}" for layer in LAYERS) + "):")
    for source in sorted(top):
        for target in sorted(top[source]):
            line = f"  {source} -> {target}"
            if source not in LAYER or target not in LAYER:
                failures.append(f"{source} -> {target}: a module missing from LAYERS")
            elif LAYER[target] >= LAYER[source]:
                failures.append(f"{source} -> {target}: imports its own or a higher layer "
                                f"({', '.join(sorted(top[source][target]))})")
                line += "   <-- upward"
            print(line)
    workflows = {s: t for s, t in edges(2).items() if s.startswith("workflows/")}
    workflows = {s: {t: f for t, f in ts.items() if t.startswith("workflows/")}
                 for s, ts in workflows.items()}
    print("the workflows:")
    for source in sorted(workflows):
        if workflows[source]:
            print(f"  {source} -> {', '.join(sorted(workflows[source]))}")
    for circle in circles(workflows):
        failures.append("the workflows import each other in a circle: " + " ↔ ".join(circle))
    if "--files" in sys.argv:
        print("circles among one module's files (listed, not failed):")
        for circle in circles(edges(4)):
            print("  " + " ↔ ".join(circle))
    for failure in failures:
        print(f"import-graph: {failure}", file=sys.stderr)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
