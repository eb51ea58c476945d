#!/usr/bin/env python3
"""The orchestrator library's import graph, checked against its layers.

Reads orchestrator/src (the library: not main.rs nor commands/, which are the binary's; not the
test modules) and collects every path a file names: its `use` trees (`crate::…`, `super::…`,
`self::…` and a child module's) and the `crate::…` and `super::…` paths in its code. A path is
followed to the module that defines the item, through the re-exports of the modules on the way
(`pub use child::Item`, a private `use` a child reaches through `super::`, a glob
`use child::*`), so a file naming `super::Item` imports the sibling file that defines it. The
script prints the edges between the top-level modules and between the workflows, and fails
(exit 1) when

- a top-level module imports one in its own or a higher layer (LAYERS, bottom first),
- the workflows (workflows/<name>) import each other in a circle, or
- the files of one module import each other in a circle (e.g. workflows/<name>/<file>, a folder
  counted as one file and its own files checked the same way).

A file naming its own parent module (an item defined there) is not counted.

    scripts/import-graph.py
"""

import os
import re
import sys
from collections import defaultdict

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "orchestrator", "src")

# Bottom first; a module may import only from the layers below its own.
LAYERS = [
    ["fsutil", "parallel", "choice", "notice"],
    ["record"],
    ["cosim", "evaluation"],
    ["twin", "blocks", "synth"],
    ["workflows"],
    ["report"],
    ["serve"],
]
LAYER = {module: i for i, layer in enumerate(LAYERS) for module in layer}

NAME = r"[A-Za-z_][A-Za-z0-9_]*"


def library_files():
    """{module path (a tuple): text without comments and test modules} of the library."""
    modules = {}
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
            text = re.sub(r"//[^\n]*", "", text)
            modules[tuple(parts)] = re.sub(r'"(?:[^"\\]|\\.)*"', '""', text)
    return modules


def use_tree(tree):
    """The paths (lists of names, `*` for a glob; the binding last) of a `use` tree's text."""
    tree = tree.strip()
    brace = tree.find("{")
    if brace < 0:
        names = [n.strip() for n in tree.split("::") if n.strip()]
        if names and " as " in names[-1]:
            names[-1] = names[-1].split(" as ")[0].strip()
        return [names] if names else []
    prefix = [n.strip() for n in tree[:brace].split("::") if n.strip()]
    inner = tree[brace + 1 : tree.rfind("}")]
    parts, depth, current = [], 0, ""
    for ch in inner:
        depth += {"{": 1, "}": -1}.get(ch, 0)
        if ch == "," and depth == 0:
            parts.append(current)
            current = ""
        else:
            current += ch
    parts.append(current)
    paths = []
    for part in parts:
        for path in use_tree(part):
            paths.append(prefix if path == ["self"] else prefix + path)
    return paths


def uses(text):
    """The `use` statements' paths of a file, and its text with them taken out."""
    found = []

    def take(m):
        found.extend(use_tree(m.group(1)))
        return ""

    rest = re.sub(r"\b(?:pub(?:\([^)]*\))?\s+)?use\s+([^;]*);", take, text)
    return found, rest


def absolute(module, path, modules):
    """`path` named in `module` from the crate's root; None for another crate's."""
    if not path:
        return None
    if path[0] == "crate":
        return path[1:]
    if path[0] in ("super", "self"):
        here = list(module)
        while path and path[0] in ("super", "self"):
            if path[0] == "super":
                here = here[:-1]
            path = path[1:]
        return here + path
    if tuple(module) + (path[0],) in modules:
        return list(module) + path
    return None


def definitions(modules):
    """{module: names of its top-level items}."""
    item = re.compile(r"^(?:pub(?:\([^)]*\))?\s+)?(?:unsafe\s+)?(?:fn|struct|enum|const|static|"
                      r"type|trait|union)\s+(" + NAME + ")", re.M)
    return {m: set(item.findall(text)) for m, text in modules.items()}


def reexports(modules):
    """{module: ({binding: absolute path}, [modules it globs])} of its `use` statements."""
    table = {}
    for module, text in modules.items():
        named, globs = {}, []
        for m in re.finditer(r"\b(?:pub(?:\([^)]*\))?\s+)?use\s+([^;]*);", text):
            for path in use_tree(m.group(1)):
                alias = re.search(r"\bas\s+(" + NAME + ")", m.group(1))
                target = absolute(module, path, modules)
                if target is None:
                    continue
                if target[-1] == "*":
                    globs.append(tuple(target[:-1]))
                else:
                    named[path[-1]] = target
        table[module] = (named, globs)
    return table


def resolve(path, modules, defs, table, seen=0):
    """The module (a tuple) that defines what the absolute `path` names."""
    path = [n for n in path if n != "*"]
    i = 0
    while i < len(path) and tuple(path[: i + 1]) in modules:
        i += 1
    module = tuple(path[:i])
    if i == len(path) or seen > 10:
        return module
    name = path[i]
    if name in defs.get(module, ()):
        return module
    named, globs = table.get(module, ({}, []))
    if name in named and named[name] != list(module) + [name]:
        return resolve(named[name] + path[i + 1 :], modules, defs, table, seen + 1)
    for g in globs:
        if name in defs.get(g, ()) or name in table.get(g, ({}, []))[0]:
            return resolve(list(g) + path[i:], modules, defs, table, seen + 1)
    return module


def imports(modules):
    """{source module: {target module: ...}} with every path followed to its definition."""
    defs, table = definitions(modules), reexports(modules)
    graph = defaultdict(set)
    for module, text in modules.items():
        paths, rest = uses(text)
        for m in re.finditer(r"\b((?:crate|super|self)(?:::" + NAME + ")+)", rest):
            paths.append(m.group(1).split("::"))
        for path in paths:
            target = absolute(module, path, modules)
            if target is None:
                continue
            target = resolve(target, modules, defs, table)
            if target and target != module and module[: len(target)] != target:
                graph[module].add(target)
    return graph


def cut(graph, depth, within=()):
    """The graph between module paths cut to `depth` names, inside `within` only; a module
    naming one of its ancestors is left out."""
    edges = defaultdict(set)
    n = len(within)
    for source, targets in graph.items():
        if source[:n] != within or len(source) <= n:
            continue
        s = source[:depth]
        for target in targets:
            if target[:n] != within or len(target) <= n:
                continue
            t = target[:depth]
            if t != s and s[: len(t)] != t and t[: len(s)] != s:
                edges[s].add(t)
    return edges


def circles(graph):
    """The strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
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
                found.append(sorted("/".join(c) for c in component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def folders(modules, within):
    """The modules under `within` that have children of their own (`within` included)."""
    return sorted({m[:d] for m in modules if m[: len(within)] == within
                   for d in range(len(within), len(m))})


def main():
    sys.setrecursionlimit(10000)
    failures = []
    modules = library_files()
    graph = imports(modules)
    top = cut(graph, 1)
    print("top-level modules (layers, bottom first: "
          + " < ".join("{" + ", ".join(layer) + "}" for layer in LAYERS) + "):")
    for (source,) in sorted(top):
        for (target,) in sorted(top[(source,)]):
            line = f"  {source} -> {target}"
            files = sorted("/".join(m) for m, ts in graph.items()
                           if m[0] == source and any(t[0] == target for t in ts))
            if source not in LAYER or target not in LAYER:
                failures.append(f"{source} -> {target}: a module missing from LAYERS")
            elif LAYER[target] >= LAYER[source]:
                failures.append(f"{source} -> {target}: imports its own or a higher layer "
                                f"({', '.join(files)})")
                line += "   <-- upward"
            print(line)
    workflows = cut(graph, 2, ("workflows",))
    print("the workflows:")
    for source in sorted(workflows):
        print(f"  {'/'.join(source)} -> "
              + ", ".join(sorted("/".join(t) for t in workflows[source])))
    for circle in circles(workflows):
        failures.append("the workflows import each other in a circle: " + " ↔ ".join(circle))
    # The files of each module (a workflow, cosim/master, …), and of each folder within one;
    # the top-level modules and the workflows are checked above.
    for folder in folders(modules, ()):
        if len(folder) < 1 or folder == ("workflows",):
            continue
        for circle in circles(cut(graph, len(folder) + 1, folder)):
            failures.append(f"the files of {'/'.join(folder)} import each other in a circle: "
                            + " ↔ ".join(circle))
    for failure in failures:
        print(f"import-graph: {failure}", file=sys.stderr)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
