"""No import circle between modules anywhere in src/.

The graph is built from the source with :mod:`ast`, not by importing: every ``import`` and ``from ... import``
statement counts, at module level, inside functions (lazy imports) and under ``if TYPE_CHECKING:`` alike, since each
says that one module needs the other. ``from pkg import name`` points at ``pkg.name`` when that is a module of
src/, else at ``pkg`` itself. Importing a module runs its packages' ``__init__`` files too; those parent edges are
left out (they would put every ``__init__`` on a circle with its own children) and ``__init__`` files are expected
to stay free of imports of their submodules.
"""

from __future__ import annotations

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"


def modules(root: Path) -> dict[str, Path]:
    """Dotted module name -> file, for every Python package under ``root/<package>/<package>/``."""
    out: dict[str, Path] = {}
    for pkg_dir in sorted(p for p in root.glob("*/*") if p.is_dir() and (p / "__init__.py").is_file()):
        base = pkg_dir.parent
        for f in pkg_dir.rglob("*.py"):
            parts = list(f.relative_to(base).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            out[".".join(parts)] = f
    return out


def _target(name: str, mods: dict[str, Path]) -> str | None:
    """The longest prefix of dotted ``name`` that is a module of src/."""
    parts = name.split(".")
    while parts:
        cand = ".".join(parts)
        if cand in mods:
            return cand
        parts.pop()
    return None


def import_graph(root: Path = SRC) -> dict[str, set[str]]:
    """Module -> the src/ modules it imports (see the module docstring)."""
    mods = modules(root)
    graph: dict[str, set[str]] = {m: set() for m in mods}
    for mod, f in mods.items():
        is_pkg = f.name == "__init__.py"
        for node in ast.walk(ast.parse(f.read_text(), str(f))):
            names: list[str] = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:  # relative: resolve against this module's package
                    pkg = mod.split(".") if is_pkg else mod.split(".")[:-1]
                    pkg = pkg[: len(pkg) - (node.level - 1)]
                    base = ".".join([*pkg, node.module] if node.module else pkg)
                else:
                    base = node.module or ""
                names = [f"{base}.{a.name}" if f"{base}.{a.name}" in mods else base for a in node.names]
            for n in names:
                t = _target(n, mods)
                if t is not None and t != mod and not mod.startswith(t + "."):
                    graph[mod].add(t)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan), each sorted; sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
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
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(out)


def test_no_import_circle_in_src():
    graph = import_graph()
    assert len(graph) > 120 and sum(map(len, graph.values())) > 300  # the graph was really built
    assert cycles(graph) == []


def _write(root: Path, rel: str, text: str) -> None:
    p = root / rel
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(text)


def test_a_planted_circle_fails(tmp_path):
    """Two modules that import each other, one lazily inside a function and one under TYPE_CHECKING, and a
    three-module ring through ``from package import module``: each is found; a clean chain is not."""
    _write(tmp_path, "pkg_a/pkg_a/__init__.py", "")
    _write(tmp_path, "pkg_a/pkg_a/one.py", "def f():\n    from pkg_a.two import g\n    return g\n")
    _write(tmp_path, "pkg_a/pkg_a/two.py", "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                                           "    from pkg_a.one import f\n")
    _write(tmp_path, "pkg_b/pkg_b/__init__.py", "")
    _write(tmp_path, "pkg_b/pkg_b/x.py", "from pkg_b import y\n")
    _write(tmp_path, "pkg_b/pkg_b/y.py", "import pkg_b.z\n")
    _write(tmp_path, "pkg_b/pkg_b/z.py", "from .x import something\n")
    _write(tmp_path, "pkg_b/pkg_b/clean.py", "from pkg_a.one import f\nimport numpy\n")
    assert cycles(import_graph(tmp_path)) == [["pkg_a.one", "pkg_a.two"], ["pkg_b.x", "pkg_b.y", "pkg_b.z"]]
    (tmp_path / "pkg_a/pkg_a/two.py").write_text("X = 1\n")
    (tmp_path / "pkg_b/pkg_b/z.py").write_text("import os\n")
    assert cycles(import_graph(tmp_path)) == []
