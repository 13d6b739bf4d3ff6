#!/usr/bin/env python3
"""Finds import circles between the modules of each crate of the workspace.

Within one crate, module A uses module B when A's code (comments and `#[cfg(test)] mod tests`
left out) names a path through B: a `use crate::b::...` or `use super::b::...` declaration,
grouped ones (`use crate::{b::X, c::Y}`) included, or a path such as `crate::b::f()` or
`super::b::T` in the code. A module and the modules inside it are one family: a child that uses
its parent, or a parent that declares its child, is no circle. A circle is a set of two or more
modules each of which reaches all the others; every one found is printed with its edges.

Exit status: 0 when no crate has a circle, 1 when one does (the test command runs this).
Usage: scripts/module_cycles.py [REPO_ROOT]
"""

import os
import re
import subprocess
import sys
from collections import defaultdict

USE = re.compile(r"^\s*(?:pub(?:\([a-z:]+\))?\s+)?use\s+([^;]+);", re.M)
PATH = re.compile(r"\b(crate|super)::([a-z_0-9:]+)")


def crate_files(root):
    """Each crate's source files, as (path, module path parts)."""
    files = subprocess.run(
        ["git", "ls-files", "--cached", "--others", "--exclude-standard", "*.rs"], cwd=root, capture_output=True, text=True, check=True
    ).stdout.split()
    crates = defaultdict(list)
    for f in files:
        if not os.path.exists(os.path.join(root, f)):
            continue
        parts = f.split("/")
        if parts[0] in ("tests", "benches", "examples") or parts[1:2] in (["tests"], ["benches"]):
            continue
        if parts[0] == "src":
            crate, rel = "evalharness", parts[1:]
        elif len(parts) >= 3:
            crate, rel = parts[0], (parts[2:] if parts[1] == "src" else parts[1:])
        else:
            continue
        crates[crate].append((f, rel))
    return crates


def module_of(rel):
    """`a/b.rs` and `a/b/mod.rs` are `a::b`; `lib.rs` and `main.rs` the crate root ``."""
    last = rel[-1][:-3]
    return "::".join(rel[:-1] if last in ("lib", "main", "mod") else rel[:-1] + [last])


def expand(tree):
    """`crate::{a::X, b::{c, d}}` as the paths it names."""
    out = []

    def walk(prefix, text):
        depth, cur, parts = 0, "", []
        for ch in text:
            depth += ch == "{"
            depth -= ch == "}"
            if ch == "," and depth == 0:
                parts.append(cur)
                cur = ""
            else:
                cur += ch
        if cur:
            parts.append(cur)
        for p in parts:
            m = re.match(r"^(.*?)::\{(.*)\}$", p)
            if m:
                walk(prefix + m.group(1) + "::", m.group(2))
            else:
                out.append(prefix + p)

    walk("", re.sub(r"\s+", "", tree))
    return out


def code_of(path):
    text = open(path, encoding="utf-8").read()
    text = re.split(r"#\[cfg\(test\)\]\s*mod tests", text)[0]
    return re.sub(r"//.*", "", text)


def edges(root, files):
    mods = {module_of(rel) for _, rel in files}
    graph = defaultdict(set)
    for path, rel in files:
        here = module_of(rel)
        parent = here.split("::")[:-1] if here else []
        code = code_of(os.path.join(root, path))
        named = [p for tree in USE.findall(code) for p in expand(tree)]
        named = [tuple(p.split("::", 1)) for p in named if p.startswith(("crate::", "super::"))]
        named += PATH.findall(code)
        for anchor, tail in named:
            segs = tail.split("::")
            base = [] if anchor == "crate" else parent
            for k in range(len(segs), 0, -1):
                target = "::".join([b for b in base if b] + segs[:k])
                if target in mods:
                    family = target == here or here.startswith(target + "::") or target.startswith(here + "::")
                    if not family:
                        graph[here].add(target)
                    break
    return graph


def circles(graph):
    """Tarjan's strongly connected components of two or more modules."""
    index, low, stack, on, found, counter = {}, {}, [], set(), [], [0]
    sys.setrecursionlimit(10000)

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def main():
    root = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), "..")
    total = 0
    for crate, files in sorted(crate_files(root).items()):
        graph = edges(root, files)
        for comp in circles(graph):
            total += 1
            print(f"{crate}: import circle between {', '.join(comp)}")
            for m in comp:
                print(f"    {m or '(crate root)'} uses {', '.join(sorted(t for t in graph[m] if t in comp))}")
    print(f"module import circles: {total}")
    return 1 if total else 0


if __name__ == "__main__":
    sys.exit(main())
