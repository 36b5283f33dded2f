#!/usr/bin/env python3
"""Import figures for a Rust module tree: files, imports between files, files in
circles, and the largest file. Usage: scripts/import-graph.py src/vk [src/xr ...]

An import is any path in a file's code (a `use` or an inline path) that names a
module of the same tree through `crate::`, `super::` or `self::`; the unit is the
file. Comments are skipped. Used for the figures in docs/ARCHITECTURE.md and in
issue notes; tests/suite/meta/tidy.rs enforces the floors themselves."""
import os
import re
import sys


def modules(crate_src, tree):
    """Map of module path (tuple) -> file, for every .rs under tree."""
    out = {}
    for root, _, files in os.walk(tree):
        for f in files:
            if not f.endswith(".rs"):
                continue
            path = os.path.join(root, f)
            rel = os.path.relpath(path, crate_src)[:-3].split(os.sep)
            if rel[-1] in ("mod", "lib", "main"):
                rel = rel[:-1]
            out[tuple(rel)] = path
    return out


PATH = re.compile(r"\b((?:crate|super|self)(?:::\{?\s*\w+)+)")


def strip_comments(text):
    # A file's unit tests (`#[cfg(test)] mod tests`, last in the file) import its parent with
    # `use super::*`: that is the file testing itself, not an import.
    text = re.split(r"#\[cfg\(test\)\]\s*mod tests\b", text)[0]
    text = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
    return "\n".join(l.split("//")[0] for l in text.splitlines())


def is_dir_module(path):
    return os.path.basename(path) in ("mod.rs", "lib.rs", "main.rs")


def edges(crate_src, mods):
    found = set()
    for mod, path in mods.items():
        code = strip_comments(open(path).read())
        # `use x::{a, b::c}` groups: expand one level
        for m in re.finditer(r"\buse\s+([^;]+);", code, flags=re.S):
            for target in expand(m.group(1)):
                add(found, mod, path, target, mods)
        for m in PATH.finditer(code):
            add(found, mod, path, m.group(1).replace("{", "").replace(" ", ""), mods)
    return found


def expand(use):
    use = re.sub(r"\s+", "", use)
    m = re.match(r"^(.*?)::\{(.*)\}$", use)
    if not m:
        return [use]
    head, body = m.groups()
    parts, depth, cur = [], 0, ""
    for ch in body:
        if ch == "," and depth == 0:
            parts.append(cur)
            cur = ""
            continue
        depth += ch == "{"
        depth -= ch == "}"
        cur += ch
    parts.append(cur)
    out = []
    for p in parts:
        if p:
            out.extend(expand(head + "::" + p))
    return out


def add(found, mod, path, target, mods):
    """Records the file that `target` (a path written in module `mod`) names, if any."""
    segs = target.split("::")
    if segs[0] == "crate":
        base, segs = [], segs[1:]
    elif segs[0] == "self":
        base, segs = list(mod), segs[1:]
    elif segs[0] == "super":
        base = list(mod)
        while segs and segs[0] == "super":
            base, segs = base[:-1], segs[1:]
    else:
        # A plain path names a crate (std, ash, ...) or an item of this module; it names another
        # file only where it starts with a child module's name.
        if tuple(list(mod) + segs[:1]) not in mods:
            return
        base = list(mod)
    full = base + segs
    for n in range(len(full), 0, -1):
        t = tuple(full[:n])
        if t in mods:
            if t != mod:
                found.add((mod, t))
            return


def sccs(nodes, es):
    graph = {n: [] for n in nodes}
    for a, b in es:
        graph[a].append(b)
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph[v]:
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
            out.append(comp)

    sys.setrecursionlimit(10000)
    for n in nodes:
        if n not in index:
            visit(n)
    return out


def report(tree):
    crate_src = tree
    while os.path.basename(crate_src) != "src" and crate_src not in ("", "/"):
        crate_src = os.path.dirname(crate_src)
    mods = modules(crate_src, tree)
    es = edges(crate_src, mods)
    comps = [c for c in sccs(list(mods), es) if len(c) > 1]
    in_circle = {n for c in comps for n in c}
    circular = [e for e in es if e[0] in in_circle and e[1] in in_circle
                and any(e[0] in c and e[1] in c for c in comps)]
    lines = {m: sum(1 for _ in open(p)) for m, p in mods.items()}
    big = max(lines, key=lines.get)
    name = lambda m: "::".join(m)
    print(f"{tree}: {len(mods)} files, {sum(lines.values())} lines, {len(es)} imports between files")
    print(f"  circles: {len(comps)} ({', '.join(str(len(c)) + ' files' for c in comps) or 'none'}); "
          f"{len(in_circle)} files in circles, {len(circular)} imports inside circles")
    for c in comps:
        print("   ", " ".join(sorted(name(m).split("::")[-1] if len(m) else name(m) for m in c)))
    print(f"  largest file: {mods[big]} ({lines[big]} lines)")
    # The same graph with each top-level folder of the tree as one unit.
    depth = len(min(mods, key=len))
    unit = lambda m: m[: depth + 1]
    top = {(unit(a), unit(b)) for a, b in es if unit(a) != unit(b)}
    units = {unit(m) for m in mods}
    top_comps = [c for c in sccs(list(units), top) if len(c) > 1]
    print(f"  top level: {len(units)} files and folders, {len(top)} imports between them, "
          f"{sum(len(c) for c in top_comps)} in circles")


for t in sys.argv[1:]:
    report(t.rstrip("/"))
