"""The package layout's rules, read from the source: imports run one way (edge <- host <- models),
no package imports itself in a circle, and no module grows past 500 lines."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("edge", "host", "models")
RANK = {name: i for i, name in enumerate(PACKAGES)}
MAX_LINES = 500


def _modules() -> dict[str, Path]:
    """Dotted name (``superbody.host.tracking.tracker``) -> file, for every module of the packages."""
    out = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            rel = path.relative_to(ROOT).with_suffix("")
            parts = list(rel.parts)
            if parts[-1] == "__init__":
                parts.pop()
            out["superbody." + ".".join(parts)] = path
    return out


MODULES = _modules()


def _is_type_checking(node: ast.If) -> bool:
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def _imports(name: str, path: Path, *, module_level: bool) -> set[str]:
    """The project modules that ``name`` imports: all of them, or only those run at import time."""
    tree = ast.parse(path.read_text(), filename=str(path))
    is_pkg = path.name == "__init__.py"
    base = name if is_pkg else name.rsplit(".", 1)[0]
    found: set[str] = set()

    def visit(nodes: list[ast.stmt] | list[ast.AST]) -> None:
        for node in nodes:
            if isinstance(node, ast.If) and _is_type_checking(node):
                continue
            if module_level and isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            if isinstance(node, ast.Import):
                found.update(a.name for a in node.names)
            elif isinstance(node, ast.ImportFrom):
                mod = node.module or ""
                if node.level:
                    anchor = base.rsplit(".", node.level - 1)[0] if node.level > 1 else base
                    mod = f"{anchor}.{mod}" if mod else anchor
                found.add(mod)
                found.update(f"{mod}.{a.name}" for a in node.names)
            visit(list(ast.iter_child_nodes(node)))

    visit(tree.body)
    return {m for m in found if m in MODULES and m != name}


def test_every_package_module_is_found() -> None:
    assert "superbody.edge.site" in MODULES and "superbody.host.aggregator" in MODULES
    assert len(MODULES) > 60


@pytest.mark.parametrize("name", sorted(MODULES))
def test_no_upward_import(name: str) -> None:
    own = RANK[name.split(".")[1]]
    upward = sorted(m for m in _imports(name, MODULES[name], module_level=False) if RANK[m.split(".")[1]] > own)
    assert not upward, f"{name} imports from a package above it: {upward} (the rule is edge <- host <- models)"


def test_no_import_circle() -> None:
    graph = {name: _imports(name, path, module_level=False) for name, path in MODULES.items()}
    # A package's __init__ importing its own submodules is how it exports its face; a submodule
    # importing a sibling through the package is then a circle through __init__, which counts.
    state: dict[str, int] = {}
    stack: list[str] = []
    circles: list[list[str]] = []

    def walk(node: str) -> None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                circles.append(stack[stack.index(nxt):] + [nxt])
            elif nxt not in state:
                walk(nxt)
        stack.pop()
        state[node] = 2

    for name in sorted(graph):
        if name not in state:
            walk(name)
    assert not circles, "import circles:\n" + "\n".join(" -> ".join(c) for c in circles)


def test_the_rule_sees_a_circle_and_an_upward_import(tmp_path: Path) -> None:
    """The checks above can fail: a made-up pair of modules that import each other, one upward."""
    a = tmp_path / "a.py"
    a.write_text("from superbody.host import aggregator\nimport superbody.edge.site\n")
    found = _imports("superbody.edge.camera", a, module_level=True)
    assert found == {"superbody.host", "superbody.host.aggregator", "superbody.edge.site"}
    assert RANK[sorted(found)[-1].split(".")[1]] > RANK["edge"]


@pytest.mark.parametrize("name", sorted(MODULES))
def test_modules_stay_small(name: str) -> None:
    lines = len(MODULES[name].read_text().splitlines())
    assert lines <= MAX_LINES, f"{MODULES[name].relative_to(ROOT)} has {lines} lines (at most {MAX_LINES})"
