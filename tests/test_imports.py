"""The import graph of src/voxgi: one-way stages, no private names across modules.

The stages run scene -> voxels -> radiosity -> display, each importing only
those before it; pipeline, distributed and cli sit above them (docs/design.md
§8). The graph is read from the source with ast, module-level and
function-level imports alike, so a cycle cannot hide inside a function.
"""

from __future__ import annotations

import ast
import functools
from pathlib import Path

import pytest

import voxgi

SRC = Path(voxgi.__file__).parent
PACKAGE = "voxgi"


def _module_name(path: Path, src: Path) -> str:
    rel = path.relative_to(src).with_suffix("")
    parts = [PACKAGE, *rel.parts]
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _resolve(module: str, node: ast.ImportFrom) -> str:
    """The absolute name of ``from <node.module> import ...`` inside ``module``."""
    if node.level == 0:
        return node.module or ""
    pkg = module.split(".") if module == PACKAGE else module.split(".")[:-1]
    base = pkg[: len(pkg) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _siblings(a: str, b: str) -> bool:
    """Whether modules ``a`` and ``b`` lie in the same subpackage of voxgi."""
    pa, pb = a.split("."), b.split(".")
    return len(pa) > 2 and len(pb) > 2 and pa[:2] == pb[:2]


def import_graph(src: Path = SRC) -> tuple[dict, list]:
    """(edges, private) of the voxgi modules under ``src``.

    ``edges[m]`` is the set of voxgi modules ``m`` imports (the package's
    ``__init__`` left out: importing a submodule runs it anyway);
    ``private`` lists ``(module, line, "other.name")`` for every private
    (underscore) name imported from another voxgi module outside the
    importer's own subpackage. Private modules themselves (``_core``,
    ``_validate``) are the package's shared internals and may be imported,
    and the modules of a subpackage (``voxgi.display.*``) share its
    internals.
    """
    files = {_module_name(p, src): p for p in sorted(src.rglob("*.py"))}
    edges: dict[str, set] = {m: set() for m in files}
    private = []
    for mod, path in files.items():
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                targets = [(a.name, None) for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = _resolve(mod, node)
                targets = []
                for a in node.names:
                    sub = f"{base}.{a.name}"
                    targets.append((sub, None) if sub in files else (base, a.name))
            else:
                continue
            for target, name in targets:
                if target not in files or target in (mod, PACKAGE):
                    continue
                edges[mod].add(target)
                if name is not None and name.startswith("_") and not _siblings(mod, target):
                    private.append((mod, node.lineno, f"{target}.{name}"))
    return edges, private


def find_cycle(edges: dict) -> list | None:
    """A cycle of ``edges`` as a list of modules (first == last), or None."""
    state: dict[str, int] = {}  # 1: on the stack, 2: done
    stack: list[str] = []

    def visit(m):
        state[m] = 1
        stack.append(m)
        for n in sorted(edges.get(m, ())):
            if state.get(n) == 1:
                return [*stack[stack.index(n) :], n]
            if n not in state:
                found = visit(n)
                if found:
                    return found
        stack.pop()
        state[m] = 2
        return None

    for m in sorted(edges):
        if m not in state:
            found = visit(m)
            if found:
                return found
    return None


@functools.cache
def voxgi_graph() -> tuple[dict, list]:
    """:func:`import_graph` of the installed voxgi, read once (the tests only read it)."""
    return import_graph()


def test_import_graph_has_no_cycle():
    edges, _ = voxgi_graph()
    assert find_cycle(edges) is None, " -> ".join(find_cycle(edges))


def test_no_module_imports_a_private_name_of_another():
    _, private = voxgi_graph()
    assert private == [], private


def _in_stage(module: str, stage: str) -> bool:
    """Whether ``module`` is the stage ``stage`` or one of its package's modules."""
    name = f"{PACKAGE}.{stage}"
    return module == name or module.startswith(name + ".")


@pytest.mark.parametrize(
    ("stage", "later"),
    [
        ("lights", ["scene", "voxels", "radiosity", "display", "pipeline", "compare", "cli"]),
        ("scene", ["voxels", "radiosity", "display", "pipeline", "distributed", "cli"]),
        ("voxels", ["solution", "radiosity", "display", "pipeline", "distributed", "cli"]),
        ("solution", ["radiosity", "display", "pipeline", "distributed", "cli"]),
        ("radiosity", ["display", "pipeline", "distributed", "cli"]),
        ("display", ["pipeline", "distributed", "compare", "cli"]),
        ("distributed", ["pipeline", "compare", "cli"]),
        ("pipeline", ["compare", "cli"]),
    ],
)
def test_stages_import_only_those_before_them(stage, later):
    edges, _ = voxgi_graph()
    # a stage may be a package: every module of it counts, and so does every
    # module of a later stage's package
    bad = {
        target
        for mod, targets in edges.items()
        if _in_stage(mod, stage)
        for target in targets
        if any(_in_stage(target, m) for m in later)
    }
    assert not bad, f"{stage} imports {sorted(bad)}"


def test_a_cycle_is_found(tmp_path):
    # the checker itself: a deliberate cycle and a private import are caught
    pkg = tmp_path / PACKAGE
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from .b import thing\n_hidden = 1\n")
    (pkg / "b.py").write_text("def thing():\n    from . import a\n    from .a import _hidden\n")
    # inside a subpackage its modules share their private names
    (pkg / "sub").mkdir()
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "sub" / "c.py").write_text("_inner = 1\n")
    (pkg / "sub" / "d.py").write_text("from .c import _inner\nfrom ..a import _hidden\n")
    edges, private = import_graph(pkg)
    assert find_cycle(edges) in (
        ["voxgi.a", "voxgi.b", "voxgi.a"],
        ["voxgi.b", "voxgi.a", "voxgi.b"],
    )
    assert private == [("voxgi.b", 3, "voxgi.a._hidden"), ("voxgi.sub.d", 2, "voxgi.a._hidden")]
