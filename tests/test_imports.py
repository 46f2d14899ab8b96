"""The package's imports, read with ``ast`` (nothing is imported): no import cycles between
modules, and no private (underscore) names imported or used across modules.

Every import counts, at module level or inside a function (a lazy import only hides a
cycle). A package's ``__init__`` importing its own submodules is the package, not a cycle.
"""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "viscx"

def module_name(path):
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def modules():
    """{module name: path} of every module of the package."""
    return {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def _resolve(name, mods):
    """The module ``name`` refers to, or None outside the package."""
    return name if name in mods else None


def imports(module, path, mods):
    """(edges, private uses) of one module.

    Returns
    -------
    edges : set of str
        Modules of the package it imports.
    private : list of (line, text)
        Underscore names of another module it imports or reads.
    """
    tree = ast.parse(path.read_text(), str(path))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    edges, private, aliases = set(), [], {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if _resolve(a.name, mods):
                    edges.add(a.name)
                    if a.asname:
                        aliases[a.asname] = a.name
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package.split(".")
                up = up[: len(up) - node.level + 1]
                base = ".".join(up + ([base] if base else []))
            for a in node.names:
                sub = f"{base}.{a.name}"
                if sub in mods:  # a submodule
                    edges.add(sub)
                    aliases[a.asname or a.name] = sub
                elif base in mods:
                    edges.add(base)
                    if a.name.startswith("_") and not a.name.startswith("__") and base != module:
                        private.append((node.lineno, f"from {base} import {a.name}"))
        elif isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name):
            target = aliases.get(node.value.id)
            if target and target != module and node.attr.startswith("_") and not node.attr.startswith("__"):
                private.append((node.lineno, f"{node.value.id}.{node.attr} ({target})"))
    edges.discard(module)
    # a package importing its own submodules (re-exports) is no dependency of theirs on it
    if path.name == "__init__.py":
        edges = {e for e in edges if not e.startswith(module + ".")}
    return edges, private


def graph():
    mods = modules()
    edges, private = {}, {}
    for name, path in mods.items():
        edges[name], private[name] = imports(name, path, mods)
    return edges, private


def cycles(edges):
    """The strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(edges.get(v, ())):
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
                out.append(sorted(comp))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return out


def test_no_import_cycles():
    edges, _ = graph()
    assert len(edges) > 60  # the walk sees the package
    found = cycles(edges)
    assert not found, "import cycles: " + "; ".join(" <-> ".join(c) for c in found)


def test_no_private_names_across_modules():
    _, private = graph()
    bad = [f"{m}:{line}: {text}" for m, uses in sorted(private.items()) for line, text in uses]
    assert not bad, "private names used across modules:\n" + "\n".join(bad)


@pytest.mark.parametrize("source, cycle, private", [
    # a lazy import closing a cycle, and a private name read through a module alias
    ({"viscx.a": "def f():\n    from viscx.b import g\n", "viscx.b": "import viscx.a as m\nx = m._h\n"}, True, True),
    # a package re-exporting its submodule, which imports a sibling: neither
    ({"viscx.p": "from viscx.p.q import r\n", "viscx.p.q": "from viscx.p.s import t\n", "viscx.p.s": "t = 1\n"}, False, False),
])
def test_the_walk_finds_what_it_must(tmp_path, source, cycle, private):
    """The checks fail on a cycle and on a private name (so they are not vacuous)."""
    global ROOT
    paths = {}
    for name, text in source.items():
        parts = name.split(".")
        is_package = any(other.startswith(name + ".") for other in source)
        path = tmp_path.joinpath(*parts, "__init__.py") if is_package else tmp_path.joinpath(*parts[:-1], parts[-1] + ".py")
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
        paths[name] = path
    saved = ROOT
    ROOT = tmp_path
    try:
        mods = {module_name(p): p for p in paths.values()}
        edges, found = {}, []
        for name, path in mods.items():
            edges[name], uses = imports(name, path, mods)
            found += uses
    finally:
        ROOT = saved
    assert bool(cycles(edges)) == cycle
    assert bool(found) == private
