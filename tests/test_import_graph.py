"""The import graph's rules (issue 18; ARCHITECTURE.md): the layering of
linksim's sub-packages, private modules kept private, no cycles, imports at
module level, argparse only in the command-line modules.

Everything is read from the source with :mod:`ast`; nothing is imported, so
a violation is reported as the file and line that commits it.
"""

from __future__ import annotations

import ast
import functools
import pathlib
from collections.abc import Iterator
from dataclasses import dataclass

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
PACKAGES = ("serialsocket", "tcpstream", "linksim")

LINKSIM_MAY_IMPORT: dict[str, set[str]] = {
    # The line and the arm are the foundations: neither imports the other.
    "link": set(),
    "arm": set(),
    "control": {"arm"},
    "bench": {"link", "arm"},
    "demo": {"link", "arm", "control"},
    # Seed 004's teleoperation: the arm's model, the line, the control station.
    "teleop": {"link", "arm", "control"},
    # The command line is the one place that may import everything.
    "cli": {"link", "arm", "control", "bench", "demo", "teleop"},
}
"""For each linksim sub-package, the sibling sub-packages it may import.  Top-level
private modules (``linksim._errors``, ``linksim._plotting``) are shared by all."""

OPTIONAL_IMPORTS = ("matplotlib", "atheris")
"""Imports allowed inside a function: the optional extras (plotting; atheris for
coverage-guided fuzzing), so that the demo and everything else run without them."""

COMMAND_LINE = {
    "serialsocket._cli",
    "serialsocket.argtypes",  # the converters (public: linksim's command line uses them)
    "serialsocket._netcat",  # the `listen` / `connect` commands: stdin/stdout and exit codes
    "serialsocket.kermit._cli",
    "serialsocket._kermit_cli",
    "tcpstream._cli",
}
"""Modules besides ``linksim.cli`` that parse command lines (argparse)."""


@dataclass(frozen=True)
class Import:
    """One imported module as written in a file, resolved to an absolute name."""

    source: str  # the importing module
    target: str  # the imported module (a submodule when `from pkg import submodule`)
    line: int
    in_function: bool


def _module_name(path: pathlib.Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


@functools.cache
def _modules() -> dict[str, pathlib.Path]:
    found: dict[str, pathlib.Path] = {}
    for top in (*PACKAGES, "fuzz", "examples"):
        for path in sorted((ROOT / top).rglob("*.py")):
            if "corpus" not in path.parts:
                found[_module_name(path)] = path
    return found


def _package_of(module: str) -> str:
    path = _modules()[module]
    return module if path.name == "__init__.py" else module.rpartition(".")[0]


@functools.cache
def _imports(module: str) -> tuple[Import, ...]:
    """What ``module`` imports, relative imports resolved."""
    tree = ast.parse(_modules()[module].read_text(encoding="utf-8"))
    nested: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            nested.update(
                id(n) for n in ast.walk(node) if isinstance(n, ast.Import | ast.ImportFrom)
            )
    package = _package_of(module)
    found: list[Import] = []
    for node in ast.walk(tree):
        inside = id(node) in nested
        if isinstance(node, ast.Import):
            found += [Import(module, a.name, node.lineno, inside) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                assert node.module is not None
                target = node.module
            for alias in node.names:
                sub = f"{target}.{alias.name}"
                found.append(
                    Import(module, sub if sub in _modules() else target, node.lineno, inside)
                )
    return tuple(found)


def _all_imports() -> Iterator[Import]:
    for module in _modules():
        yield from _imports(module)


def _where(imp: Import) -> str:
    return f"{_modules()[imp.source].relative_to(ROOT)}:{imp.line} imports {imp.target}"


def test_linksim_sub_packages_import_only_what_lies_below() -> None:
    bad = []
    for imp in _all_imports():
        src, dst = imp.source.split("."), imp.target.split(".")
        if src[0] != "linksim" or dst[0] != "linksim" or len(src) < 2 or len(dst) < 2:
            continue
        if src[1] not in LINKSIM_MAY_IMPORT or dst[1] not in LINKSIM_MAY_IMPORT:
            continue  # a top-level module: the face, shared errors, plotting
        if dst[1] != src[1] and dst[1] not in LINKSIM_MAY_IMPORT[src[1]]:
            bad.append(_where(imp))
    assert not bad, "linksim sub-packages out of order:\n" + "\n".join(bad)


def test_every_linksim_module_lives_in_its_sub_package() -> None:
    loose = [
        name
        for name, path in _modules().items()
        if name.startswith("linksim.")
        and name.count(".") == 1
        and path.name != "__init__.py"
        and name not in {"linksim._errors", "linksim._plotting", "linksim.__main__"}
    ]
    assert not loose, f"modules outside linksim's sub-packages: {loose}"


def _private_parent(target: str) -> str | None:
    """The package that owns the first private component of ``target``, if any."""
    parts = target.split(".")
    for i, part in enumerate(parts):
        if part.startswith("_") and not part.startswith("__"):
            return ".".join(parts[:i])
    return None


def test_no_module_reaches_into_another_package_s_private_modules() -> None:
    bad = []
    for imp in _all_imports():
        owner = _private_parent(imp.target)
        if owner is None or imp.target.split(".")[0] not in (*PACKAGES, "fuzz", "examples"):
            continue
        package = _package_of(imp.source)
        if package != owner and not package.startswith(owner + "."):
            bad.append(_where(imp))
    assert not bad, "private modules imported from outside their package:\n" + "\n".join(bad)


def _strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's algorithm, iterative: the components with more than one module."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components: list[list[str]] = []
    counter = 0
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, successors = work[-1]
            for nxt in successors:
                if nxt not in index:
                    index[nxt] = low[nxt] = counter
                    counter += 1
                    stack.append(nxt)
                    on_stack.add(nxt)
                    work.append((nxt, iter(sorted(graph[nxt]))))
                    break
                if nxt in on_stack:
                    low[node] = min(low[node], index[nxt])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == node:
                            break
                    if len(component) > 1:
                        components.append(sorted(component))
    return components


def test_the_strongly_connected_helper_finds_a_cycle() -> None:
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert _strongly_connected(graph) == [["a", "b", "c"]]
    assert _strongly_connected({"a": {"b"}, "b": set()}) == []


def test_no_import_cycles_between_modules() -> None:
    modules = _modules()
    graph: dict[str, set[str]] = {name: set() for name in modules}
    for imp in _all_imports():
        if imp.target in modules and imp.target != imp.source:
            graph[imp.source].add(imp.target)
    cycles = _strongly_connected(graph)
    assert not cycles, f"import cycles: {cycles}"


def test_imports_are_at_module_level() -> None:
    """An import inside a function hides a dependency (and often a cycle);
    only the optional plotting library is imported where it is used."""
    bad = [
        _where(imp)
        for imp in _all_imports()
        if imp.in_function and not imp.target.startswith(OPTIONAL_IMPORTS)
    ]
    assert not bad, "imports inside functions:\n" + "\n".join(bad)


@pytest.mark.parametrize("package", PACKAGES)
def test_argparse_only_in_command_line_modules(package: str) -> None:
    bad = [
        _where(imp)
        for imp in _all_imports()
        if imp.target.split(".")[0] == "argparse"
        and imp.source.split(".")[0] == package
        and not imp.source.startswith("linksim.cli")
        and imp.source not in COMMAND_LINE
    ]
    assert not bad, "argparse outside the command line:\n" + "\n".join(bad)
