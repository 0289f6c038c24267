"""The layers of docs/architecture.md, read from every module's imports (those inside functions too)."""

import ast
import shutil
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "parsim"

# Bottom to top, as docs/architecture.md draws them: a module imports from its own layer or
# below; a method imports no other method; a module named in no layer is in the top one.
LAYERS = (
    ("kernels", ("parsim.core",)),
    ("base", ("parsim.errors", "parsim.version")),
    ("parallel", ("parsim.parallel",)),
    ("foundations", ("parsim.parameters", "parsim.solver", "parsim.machine", "parsim.phases", "parsim.progress",
                     "parsim.interrupts", "parsim.options", "parsim.agglomerate_file", "parsim.output.atomic",
                     "parsim.output.snapshot")),
    ("methods", ("parsim.deposition", "parsim.aggregation")),
    ("registry", ("parsim.solvers",)),
    ("application", ("parsim",)),
)


def _place(module: str) -> tuple[int, str]:
    """(layer number, the prefix that placed it): the longest prefix that names the module or a package of it."""
    return max((len(prefix), number, prefix) for number, (_, prefixes) in enumerate(LAYERS) for prefix in prefixes
               if module == prefix or module.startswith(prefix + "."))[1:]


def _imports(path: Path, module: str, modules: set) -> set:
    """The parsim modules that ``path`` imports, outside ``if TYPE_CHECKING:`` blocks."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and ast.unparse(node.test).endswith("TYPE_CHECKING"):
            node.body = []
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = ".".join(package.split(".")[:len(package.split(".")) + 1 - node.level] + [node.module or ""]
                            ).strip(".") if node.level else node.module
            found |= {f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in node.names}
    return {name for name in found if name == "parsim" or name.startswith("parsim.")}


def violations(package: Path) -> list[str]:
    """Every import against the layers, and every cycle of imports, in the tree ``package``."""
    files = {".".join(p.relative_to(package.parent).with_suffix("").parts).removesuffix(".__init__"): p
             for p in sorted(package.rglob("*.py"))}
    graph = {module: _imports(path, module, set(files)) for module, path in files.items()}
    found = []
    for module, targets in graph.items():
        (layer, prefix) = _place(module)
        for target in sorted(targets):
            (target_layer, target_prefix) = _place(target)
            if target_layer > layer or (LAYERS[layer][0] == "methods" and target_layer == layer != 0
                                        and target_prefix != prefix):
                found.append(f"{module} ({LAYERS[layer][0]}) imports {target} ({LAYERS[target_layer][0]})")
    state = {}

    def visit(module, path):  # depth first; a module met again on the current path closes a cycle
        state[module] = "open"
        for target in sorted(graph.get(module, ())):
            if state.get(target) == "open":
                found.append("cycle: " + " -> ".join(path[path.index(target):] + [target]))
            elif target not in state:
                visit(target, path + [target])
        state[module] = "done"

    for module in graph:
        if module not in state:
            visit(module, [module])
    return found


def test_every_import_keeps_the_layers_and_none_closes_a_cycle():
    assert violations(PACKAGE) == []


@pytest.mark.parametrize("module, planted, expected", [
    ("core/statistics.py", "    from parsim.errors import JobError\n", "parsim.core.statistics (kernels) imports"),
    ("parallel/halo.py", "from parsim.deposition import spread\n", "parsim.parallel.halo (parallel) imports"),
    ("aggregation/tiled.py", "from parsim.deposition.spread import drop_order\n", "(methods) imports parsim.depo"),
    ("output/rows.py", "from parsim.output.folder import OutputFolder\n", "cycle: "),
])
def test_a_planted_import_is_found(tmp_path, module, planted, expected):
    shutil.copytree(PACKAGE, tmp_path / "parsim", ignore=shutil.ignore_patterns("__pycache__"))
    path = tmp_path / "parsim" / module
    source = path.read_text(encoding="utf-8")
    if planted.startswith(" "):  # an import inside a function
        planted = "def _planted():\n" + planted
    path.write_text(source + "\n\n" + planted, encoding="utf-8")
    assert any(expected in line for line in violations(tmp_path / "parsim"))
