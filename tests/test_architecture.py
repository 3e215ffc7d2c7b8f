"""The import graph of canest/: no circle, and no import from a lower layer up to a higher one.

Layers, bottom to top (README "Architecture"): a module may import its own
layer and the ones below. Imports deferred into functions count too: they
are read from the source, not from what happens to run.
"""
import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "canest"

LAYERS = [  # bottom first
    ("canest", "canest.errors", "canest.params", "canest.calibration", "canest.signals"),
    ("canest.models", "canest.filters"),
    ("canest.settings",),
    ("canest.estimation", "canest.codec", "canest.resample", "canest.io"),
    ("canest.config", "canest.yamldoc", "canest.limits", "canest.pipeline"),
    ("canest.apps", "canest.sim"),
    ("canest.cli", "canest.commands", "canest.__main__"),
]


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def layer(module: str) -> int:
    """The layer of a module: the longest matching prefix in LAYERS."""
    best = None
    for rank, prefixes in enumerate(LAYERS):
        for prefix in prefixes:
            inside = module == prefix or (prefix != "canest" and module.startswith(prefix + "."))
            if inside and (best is None or len(prefix) > best[1]):
                best = (rank, len(prefix))
    assert best is not None, f"{module} is in no layer: add it to LAYERS and to the README's architecture"
    return best[0]


def imports_of(path: Path) -> set:
    """The canest modules a file imports (``from canest.x import y`` counts y if it is a module)."""
    modules = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            modules.update(alias.name for alias in node.names if alias.name.startswith("canest"))
        elif isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("canest"):
            for alias in node.names:
                candidate = f"{node.module}.{alias.name}"
                is_module = (PACKAGE.parent / Path(*candidate.split("."))).with_suffix(".py").is_file() or \
                    (PACKAGE.parent / Path(*candidate.split("."))).is_dir()
                modules.add(candidate if is_module else node.module)
    return modules


def graph() -> dict:
    return {module_name(path): imports_of(path) for path in PACKAGE.rglob("*.py")}


def upward(imports: dict) -> list:
    return [f"{module} (layer {layer(module)}) imports {target} (layer {layer(target)})"
            for module, targets in imports.items() for target in targets if layer(target) > layer(module)]


def circles(imports: dict) -> list:
    edges = {module: {t for t in targets if t != module} for module, targets in imports.items()}
    state = {}
    found = []

    def visit(module, path):
        state[module] = "open"
        for target in sorted(edges.get(module, ())):
            if state.get(target) == "open":
                found.append(" -> ".join(path[path.index(target):] + [target]))
            elif target not in state:
                visit(target, path + [target])
        state[module] = "done"

    for module in sorted(edges):
        if module not in state:
            visit(module, [module])
    return found


def test_no_import_runs_up_a_layer():
    problems = upward(graph())
    assert not problems, "\n".join(problems)


def test_no_import_circle():
    found = circles(graph())
    assert not found, "\n".join(found)


def test_the_checks_see_an_upward_import_and_a_circle():
    """The rules have teeth: the import circle of the old layout (a model importing the config loader) is caught."""
    old = {"canest.models.single_track": {"canest.config"}, "canest.config": {"canest.models.single_track"}}
    assert upward(old) == ["canest.models.single_track (layer 1) imports canest.config (layer 4)"]
    assert circles(old) == ["canest.config -> canest.models.single_track -> canest.config"]
