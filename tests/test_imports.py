"""The package's import graph: no cycles, and the layers of DESIGN §2 kept.

Every ``import`` statement of every module counts, those inside functions and under
``TYPE_CHECKING`` too: a cycle hidden in a function is still two modules that cannot be
understood one without the other. Importing ``quilting.a.b`` runs ``quilting/__init__`` first,
but only the named module counts as an edge (else every module would lean on the package).
"""

from __future__ import annotations

import ast
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SERVER = ROOT / "server"
CLIENT = ROOT / "client" / "quilting_client"

#: Outside libraries and the only modules (or packages, by prefix) that may import them.
OWNERS = {
    "numba": ("quilting.core.kernels",),
    "moderngl": ("quilting.costs.gl",),
    "PIL": ("quilting.io",),
    "fastapi": ("quilting.service",),
    "starlette": ("quilting.service",),
    "pydantic": ("quilting.service",),
    "uvicorn": ("quilting.service",),
    "redis": ("quilting.service",),
    "dramatiq": ("quilting.service",),
}


def modules(server: Path) -> dict[str, Path]:
    """Dotted name -> file of every module of the ``quilting`` package under ``server``."""
    found = {}
    for path in sorted((server / "quilting").rglob("*.py")):
        parts = list(path.relative_to(server).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        found[".".join(parts)] = path
    return found


def _statements(path: Path, name: str) -> Iterator[tuple[str, list[str]]]:
    """``(module, names)`` of each import statement of the module ``name``, relative imports
    made absolute."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, []
        elif isinstance(node, ast.ImportFrom):
            module = node.module or ""
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                module = ".".join([*base, module] if module else base)
            yield module, [alias.name for alias in node.names]


def graph(server: Path) -> tuple[dict[str, set[str]], dict[str, set[str]]]:
    """``(internal, external)``: for each module, the package's modules it imports and the
    top-level names of the outside libraries it imports."""
    known = modules(server)
    internal: dict[str, set[str]] = {name: set() for name in known}
    external: dict[str, set[str]] = {name: set() for name in known}
    for name, path in known.items():
        for module, names in _statements(path, name):
            if module != "quilting" and not module.startswith("quilting."):
                external[name].add(module.split(".")[0])
                continue
            # ``from quilting.core import kernels`` names a module; ``from quilting import x``
            # a value of the package.
            targets = [f"{module}.{n}" for n in names if f"{module}.{n}" in known]
            if not targets:
                while module not in known and "." in module:
                    module = module.rpartition(".")[0]
                targets = [module]
            internal[name].update(t for t in targets if t != name)
    return internal, external


def cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for nxt in sorted(edges.get(node, ())):
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = []
            while True:
                top = stack.pop()
                on_stack.discard(top)
                component.append(top)
                if top == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(edges):
        if node not in index:
            visit(node)
    return found


def _under(name: str, prefix: str) -> bool:
    return name == prefix or name.startswith(prefix + ".")


INTERNAL, EXTERNAL = graph(SERVER)


def _imports(
    importer: Callable[[str], bool], imported: Callable[[str], bool]
) -> set[tuple[str, str]]:
    """The package's imports (module, what it imports) from a module ``importer`` accepts of
    a module ``imported`` accepts."""
    return {
        (name, target)
        for name, targets in INTERNAL.items()
        if importer(name)
        for target in targets
        if imported(target)
    }


def test_the_graph_sees_the_package() -> None:
    # A parser that found nothing would pass every rule below.
    assert {"quilting", "quilting.api", "quilting.core.synthesis", "quilting.service.app"} <= set(
        INTERNAL
    )
    assert "quilting.core.synthesis" in INTERNAL["quilting.api"]
    assert "quilting.core.kernels" in INTERNAL["quilting.core.synthesis"]
    assert "numpy" in EXTERNAL["quilting.core.synthesis"]


def test_no_import_cycles() -> None:
    assert cycles(INTERNAL) == []


def test_cycles_are_found() -> None:
    edges = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": {"e"}}
    assert cycles(edges) == [["a", "b", "c"]]


def test_a_cycle_through_a_function_level_import_counts(tmp_path: Path) -> None:
    package = tmp_path / "quilting"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "one.py").write_text("from quilting.two import X\n")
    (package / "two.py").write_text("X = 1\n\ndef f():\n    from quilting import one\n")
    assert cycles(graph(tmp_path)[0]) == [["quilting.one", "quilting.two"]]


@pytest.mark.parametrize("layer", ["quilting.service", "quilting.cli"])
def test_the_upper_layers_use_the_public_api(layer: str) -> None:
    """DESIGN: the service and the command line import ``quilting``, ``quilting.backends``,
    ``quilting.options``, ``quilting.io`` (and ``quilting.api``), never the engine's insides."""
    offending = _imports(
        lambda name: _under(name, layer),
        lambda target: _under(target, "quilting.core") or _under(target, "quilting.costs"),
    )
    assert offending == set()


def test_the_core_imports_only_the_core() -> None:
    offending = _imports(
        lambda name: _under(name, "quilting.core"),
        lambda target: not _under(target, "quilting.core"),
    )
    assert offending == set()


def test_the_backends_import_only_the_core_and_each_other() -> None:
    offending = _imports(
        lambda name: _under(name, "quilting.costs"),
        lambda target: not (_under(target, "quilting.core") or _under(target, "quilting.costs")),
    )
    assert offending == set()


def test_nothing_below_the_service_imports_it() -> None:
    # ``python -m quilting`` is the command line itself.
    top = ("quilting.service", "quilting.cli", "quilting.__main__")
    offending = _imports(
        lambda name: not any(_under(name, layer) for layer in top),
        lambda target: _under(target, "quilting.service") or target == "quilting.cli",
    )
    assert offending == set()


@pytest.mark.parametrize("library", sorted(OWNERS))
def test_each_outside_library_lives_in_one_place(library: str) -> None:
    users = {name for name, libraries in EXTERNAL.items() if library in libraries}
    strays = {name for name in users if not any(_under(name, p) for p in OWNERS[library])}
    assert strays == set()


def test_the_client_never_imports_the_engine() -> None:
    offending = []
    for path in sorted(CLIENT.rglob("*.py")):
        for module, _ in _statements(path, "quilting_client." + path.stem):
            if module == "quilting" or module.startswith("quilting."):
                offending.append((path.name, module))
    assert offending == []
