"""The house's layers (docs/architecture.md): every import of hdrio/ and plugins/ points
down, or stays inside its own package; packages side by side never import each other.

Imports inside functions count (a lazy import is still an arrow); imports under
``if TYPE_CHECKING:`` do not (they never run).
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

LAYERS: tuple[tuple[str, frozenset[str]], ...] = (
    ("foundations", frozenset({
        "hdrio.errors", "hdrio.lazy", "hdrio.float_bits", "hdrio.numbers", "hdrio.parallel",
        "hdrio.jit", "hdrio.method_registry", "hdrio.stack", "hdrio.skips"})),
    ("io", frozenset({"hdrio.io"})),
    ("radiometry", frozenset({"hdrio.radiometry"})),
    ("stages", frozenset({"hdrio.response", "hdrio.align", "hdrio.merge", "hdrio.tonemap",
                          "hdrio.cms"})),
    ("job", frozenset({"hdrio.job"})),
    ("shoots and tools", frozenset({"hdrio.batch", "hdrio.tools"})),
    ("front ends", frozenset({"hdrio.cli", "plugins.blender"})),
)
"""Bottom to top. Within foundations, modules may import each other (one way: no
circle, the test below); within every other layer, packages side by side may not."""

FACE = "hdrio"
"""The package's face (``hdrio/__init__.py``): any module may read ``__version__`` there."""


def _unit(module: str) -> str:
    """The layer unit of ``module``: its package, or the module itself at the top level
    (``python -m hdrio`` is the command line's)."""
    if module == "hdrio.__main__":
        return "hdrio.cli"
    for _, units in LAYERS:
        for unit in units:
            if module == unit or module.startswith(unit + "."):
                return unit
    return module


def _rank(unit: str) -> int:
    for rank, (_, units) in enumerate(LAYERS):
        if unit in units:
            return rank
    raise AssertionError(f"{unit} belongs to no layer: add it to LAYERS and to "
                         "docs/architecture.md")


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _imports(path: Path) -> set[str]:
    """Modules (and ``module.name`` for names imported from them) that ``path`` imports."""
    tree = ast.parse(path.read_text())
    skip: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            skip |= {id(n) for branch in node.body for n in ast.walk(branch)}
    module = _module_name(path)
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found = set()
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(parts + ([base] if base else []))
            found.add(base)
            found |= {f"{base}.{alias.name}" for alias in node.names}
    return found


def _as_module(target: str) -> str | None:
    """The module of ours a dotted import names, else ``None``."""
    parts = target.split(".")
    while parts:
        candidate = ROOT.joinpath(*parts)
        if candidate.with_suffix(".py").is_file() or (candidate / "__init__.py").is_file():
            return ".".join(parts)
        parts = parts[:-1]
    return None


def _graph() -> dict[str, set[str]]:
    sources = sorted((ROOT / "hdrio").rglob("*.py")) + sorted(
        (ROOT / "plugins" / "blender").glob("*.py"))
    graph = {}
    for path in sources:
        if path.name == "build.py" or "ci" in path.relative_to(ROOT).parts:
            continue  # the extension's build script and CI helpers are not the add-on
        module = _module_name(path)
        targets = {_as_module(t) for t in _imports(path)} - {None, module}
        graph[module] = {t for t in targets if t.startswith(("hdrio", "plugins"))}
    return graph


GRAPH = _graph()


def _arrows() -> list[tuple[str, str]]:
    return [(source, target) for source, targets in GRAPH.items() for target in targets]


def test_every_module_belongs_to_a_layer():
    for module in GRAPH:
        if module != FACE:
            _rank(_unit(module))


def _against_the_layers(source: str, target: str) -> str | None:
    """Why the arrow ``source -> target`` runs against the layers, else ``None``."""
    if FACE in (source, target):
        return None  # __version__, and the face's own lazy table (strings, not imports)
    unit, other = _unit(source), _unit(target)
    if unit == other:
        return None  # inside one package
    rank, other_rank = _rank(unit), _rank(other)
    if other_rank < rank or rank == other_rank == 0:
        return None  # down; or foundations using each other (no circle: below)
    where = "beside" if other_rank == rank else "above"
    return f"{source} -> {target}: {other} is {where} {unit}"


def test_every_import_points_down_the_layers():
    wrong = [why for why in (_against_the_layers(*arrow) for arrow in _arrows()) if why]
    assert not wrong, "imports against the layers (docs/architecture.md):\n" + "\n".join(wrong)


def test_the_layer_test_sees_an_upward_import():
    assert _against_the_layers("hdrio.align.motion", "hdrio.merge.masked")
    assert _against_the_layers("hdrio.io.raw", "hdrio.cms.encoding")
    assert _against_the_layers("hdrio.radiometry.noise", "hdrio.job.plan")
    assert _against_the_layers("hdrio.job.run", "hdrio.merge.masked") is None


def test_named_arrows_that_ran_against_the_data_are_gone():
    forbidden = [("hdrio.align", "hdrio.merge"), ("hdrio.response", "hdrio.merge"),
                 ("hdrio.io", "hdrio.cms"), ("hdrio.radiometry", "hdrio.response")]
    for source, target in _arrows():
        for low, high in forbidden:
            assert not (_unit(source) == low and _unit(target) == high), (source, target)


def test_the_top_level_holds_only_the_face_and_foundations():
    top = {f"hdrio.{p.stem}" for p in (ROOT / "hdrio").glob("*.py")
           if p.stem not in ("__init__", "__main__")}
    assert top == set(LAYERS[0][1]), sorted(top ^ set(LAYERS[0][1]))


def test_no_import_circle_between_modules():
    done: set[str] = set()

    def visit(module: str, path: tuple[str, ...]) -> None:
        assert module not in path, " -> ".join((*path, module))
        if module in done:
            return
        for other in GRAPH.get(module, ()):
            # A package's face importing its own modules is how a package is made.
            if other != FACE and not other.startswith(module + "."):
                visit(other, (*path, module))
        done.add(module)

    for module in GRAPH:
        visit(module, ())


def test_the_core_never_imports_its_front_ends():
    for source, target in _arrows():
        if source.startswith("hdrio.") and not source.startswith(("hdrio.cli", "hdrio.__main__")):
            assert not target.startswith(("hdrio.cli", "plugins")), (source, target)
    for path in (ROOT / "hdrio").rglob("*.py"):
        text = path.read_text()
        assert "import bpy" not in text and "from bpy" not in text, path
