"""The house (DESIGN.md): no import circles, and dependencies that point one way.

Walks every module of the package with `ast` (no third-party tool) and collects the eyehil modules it
imports, at module level or inside functions alike (a lazy import is still a dependency). A module depends
on the module it names (``import eyehil.a.b`` and ``from eyehil.a import b`` name ``eyehil.a.b`` when that is a
module), not on its parent packages' ``__init__``.

The one-way rule: protocols imports no other layer; drivers imports protocols; emulator imports protocols and,
of the host side, only the pure estimators in drivers/gaze; analysis may import all three. `eyehil.parallel`
(chunks of work on a process pool or Dask), `eyehil.stopping` (a command's wait for SIGTERM) and `eyehil.cbuild`
(a C helper built on first use) lie below every layer: they import no eyehil module, and the layers may use
them.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LAYERS = ("emulator", "drivers", "protocols", "analysis")
ALLOWED: dict[str, tuple[str, ...]] = {
    "protocols": ("eyehil.protocols", "eyehil.cbuild"),
    "drivers": ("eyehil.drivers", "eyehil.protocols", "eyehil.stopping"),
    "emulator": ("eyehil.emulator", "eyehil.protocols", "eyehil.drivers.gaze", "eyehil.parallel", "eyehil.stopping",
                 "eyehil.cbuild"),
    "analysis": ("eyehil.analysis", "eyehil.emulator", "eyehil.drivers", "eyehil.protocols", "eyehil.parallel",
                 "eyehil.stopping", "eyehil.cbuild"),
}
LEAVES = ("eyehil.parallel", "eyehil.stopping", "eyehil.cbuild")  # below the layers: they import no eyehil module


def _modules() -> dict[str, Path]:
    found = {}
    for layer in ("eyehil", *LAYERS):
        base = ROOT / layer
        for path in base.rglob("*.py"):
            parts = path.relative_to(base).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            if any("+" in p for p in parts):
                continue  # pyserial's handler modules (protocol_eyehil+loop): aliases of urlhandlers.serial_port
            name = ".".join(("eyehil",) if layer == "eyehil" else ("eyehil", layer)) + "".join("." + p for p in parts)
            found[name] = path
    return found


MODULES = _modules()


def _imports(name: str, path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*parts, base] if base else parts)
            for a in node.names:
                out.add(f"{base}.{a.name}" if f"{base}.{a.name}" in MODULES else base)
    return {m for m in out if m in MODULES and m != name}


GRAPH = {name: _imports(name, path) for name, path in MODULES.items()}


def test_the_package_is_found() -> None:
    assert {"eyehil", "eyehil.cli", "eyehil.emulator.forward", "eyehil.drivers.client"} <= MODULES.keys()
    assert len(MODULES) > 150


def test_no_module_imports_the_old_top_level_names() -> None:
    offenders = []
    for name, path in MODULES.items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else (
                [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level else [])
            offenders += [f"{name}: {n}" for n in names if n.split(".")[0] in (*LAYERS, "eyehil_cli")]
    assert not offenders


def test_no_import_circles() -> None:
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    cycles: list[list[str]] = []

    def visit(v: str) -> None:  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in GRAPH[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    for v in sorted(GRAPH):
        if v not in index:
            visit(v)
    assert not cycles, f"import circles: {cycles}"


@pytest.mark.parametrize("layer", LAYERS)
def test_dependencies_point_one_way(layer: str) -> None:
    prefix = f"eyehil.{layer}"
    wrong = sorted(f"{name} -> {dep}" for name, deps in GRAPH.items() if name == prefix or name.startswith(prefix + ".")
                   for dep in deps if not any(dep == a or dep.startswith(a + ".") for a in ALLOWED[layer]))
    assert not wrong, "imports against DESIGN.md's one-way rule:\n" + "\n".join(wrong)


@pytest.mark.parametrize("leaf", LEAVES)
def test_shared_leaves_import_no_eyehil_module(leaf: str) -> None:
    assert leaf in MODULES and not GRAPH[leaf]


def test_the_walker_sees_a_circle_and_a_wrong_way_import(tmp_path: Path) -> None:
    """The checks above could fail: a made-up pair of modules shows both findings."""
    saved = dict(GRAPH)
    try:
        GRAPH["eyehil.protocols.crc"] = GRAPH["eyehil.protocols.crc"] | {"eyehil.protocols.cobs",
                                                                         "eyehil.drivers.client"}
        GRAPH["eyehil.protocols.cobs"] = GRAPH["eyehil.protocols.cobs"] | {"eyehil.protocols.crc"}
        with pytest.raises(AssertionError, match="circles"):
            test_no_import_circles()
        with pytest.raises(AssertionError, match="one-way"):
            test_dependencies_point_one_way("protocols")
    finally:
        GRAPH.clear()
        GRAPH.update(saved)


def test_every_folder_of_python_modules_is_a_package() -> None:
    """setup.py installs packages (folders with __init__.py): a folder without one is left out of the wheel."""
    folders = {p.parent for layer in ("eyehil", *LAYERS) for p in (ROOT / layer).rglob("*.py")}
    assert not sorted(str(f.relative_to(ROOT)) for f in folders if not (f / "__init__.py").is_file())


def test_every_package_docstring_names_its_modules() -> None:
    missing = []
    for name, path in MODULES.items():
        if path.name != "__init__.py":
            continue
        doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"))) or ""
        children = [p for p in path.parent.iterdir() if "+" not in p.name and (
            (p.suffix == ".py" and p.name != "__init__.py") or (p / "__init__.py").is_file())]
        missing += [f"{name}: {c.stem}" for c in children if f"`{c.stem}" not in doc]
    assert not missing, "package docstrings that do not name a module:\n" + "\n".join(missing)
