"""The packages' imports run one way: envs <- baselines <- training, its layers bottom to top, no cycles.

The test reads every module's source (nothing is imported) and collects its imports of the project's
own modules, at module level and inside functions alike.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("agri_envs", "agri_baselines", "agri_training")
#: ``agri_training``'s layers, bottom first: a module may import from its own layer and those below.
TRAINING_LAYERS = (
    ("agri_training.core",),
    ("agri_training.learned",),
    ("agri_training.evaluation",),
    ("agri_training.leaderboard",),
    ("agri_training.datasets",),
    ("agri_training.report",),
    ("agri_training.train",),
    ("agri_training.sweep",),
    ("agri_training.tune",),
    ("agri_training.cli",),
)
#: Third-party packages that may be imported inside a function, to defer their import cost or to keep
#: them optional (torch and what builds on it, plotting, Ray, pybullet, video).
DEFERRABLE = {
    "torch", "stable_baselines3", "sb3_contrib", "supersuit", "matplotlib", "ray", "optuna", "pybullet",
    "pybullet_data", "moviepy", "imageio", "imageio_ffmpeg", "pygame", "tqdm", "tensorboard", "psutil", "numba",
    "scipy", "PIL", "mkdocs", "minari", "h5py", "onnx",
}  # fmt: skip


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def modules() -> dict[str, Path]:
    return {module_name(p): p for pkg in PACKAGES for p in sorted((ROOT / pkg).rglob("*.py"))}


def resolve(name: str, known: dict[str, Path]) -> str | None:
    """The project module an imported dotted name lands in (the longest known prefix), or None."""
    parts = name.split(".")
    for k in range(len(parts), 0, -1):
        candidate = ".".join(parts[:k])
        if candidate in known:
            return candidate
    return None


def _mark_functions(tree: ast.AST) -> None:
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            for inner in ast.walk(node):
                inner._in_function = True  # type: ignore[attr-defined]


def graph() -> dict[str, list[tuple[str, int, bool, list[str]]]]:
    known = modules()
    out = {}
    for name, path in known.items():
        tree = ast.parse(path.read_text())
        _mark_functions(tree)
        out[name] = _imports_of_tree(tree, path, known)
    return out


def _imports_of_tree(tree: ast.AST, path: Path, known: dict[str, Path]) -> list[tuple[str, int, bool, list[str]]]:
    """``(imported project module, line, inside a function, imported names)`` of one parsed file."""
    me = module_name(path)
    package = me if path.name == "__init__.py" else me.rpartition(".")[0]
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [(a.name, [a.asname or a.name]) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                keep = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(keep + ([base] if base else []))
            names = [((f"{base}.{a.name}" if f"{base}.{a.name}" in known else base), [a.name]) for a in node.names]
        else:
            continue
        for name, items in names:
            target = resolve(name, known)
            if target is not None and target != me:
                out.append((target, node.lineno, bool(getattr(node, "_in_function", False)), items))
    return out


GRAPH = graph()


def package_of(module: str) -> str:
    return module.split(".")[0]


def layer_of(module: str) -> int | None:
    for rank, prefixes in enumerate(TRAINING_LAYERS):
        if any(module == p or module.startswith(p + ".") for p in prefixes):
            return rank
    return None


def test_packages_import_downwards_only():
    rank = {"agri_envs": 0, "agri_baselines": 1, "agri_training": 2}
    wrong = [
        f"{src}:{line} imports {dst}"
        for src, edges in GRAPH.items()
        for dst, line, _, _ in edges
        if rank[package_of(dst)] > rank[package_of(src)]
    ]
    assert not wrong, "\n".join(wrong)


def test_training_layers_import_downwards_only():
    wrong = []
    for src, edges in GRAPH.items():
        src_layer = layer_of(src)
        for dst, line, _, _ in edges:
            dst_layer = layer_of(dst)
            if src_layer is not None and dst_layer is not None and dst_layer > src_layer:
                wrong.append(f"{src}:{line} imports {dst} (a layer above)")
    assert not wrong, "\n".join(wrong)


def test_no_import_cycle():
    edges = {src: {dst for dst, *_ in out if not dst.startswith(src + ".")} for src, out in GRAPH.items()}
    # A package's __init__ importing its own submodules is how packages export; it is not a cycle.
    colour: dict[str, int] = {}
    stack: list[str] = []
    cycles: list[str] = []

    def visit(node: str) -> None:
        colour[node] = 1
        stack.append(node)
        for nxt in sorted(edges.get(node, ())):
            if colour.get(nxt) == 1:
                cycles.append(" -> ".join(stack[stack.index(nxt) :] + [nxt]))
            elif nxt not in colour:
                visit(nxt)
        stack.pop()
        colour[node] = 2

    for node in sorted(edges):
        if node not in colour:
            visit(node)
    assert not cycles, "\n".join(cycles)


def same_package_module(src: str, dst: str, name: str) -> bool:
    """``from package import _module`` inside that package: a package-private module, used where it belongs."""
    return dst.endswith("." + name) and dst.rpartition(".")[0] == src.rpartition(".")[0]


def test_no_private_name_crosses_a_module():
    wrong = [
        f"{src}:{line} imports {name} from {dst}"
        for src, out in GRAPH.items()
        for dst, line, _, names in out
        for name in names
        if name.startswith("_") and not name.startswith("__") and not same_package_module(src, dst, name)
    ]
    assert not wrong, "\n".join(wrong)


def heavy(module: str) -> bool:
    """A project module whose own module-level imports include a library worth deferring (or numba kernels)."""
    tree = ast.parse(modules()[module].read_text())
    for node in tree.body:
        if isinstance(node, ast.Import):
            tops = {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and not node.level:
            tops = {(node.module or "").split(".")[0]}
        else:
            continue
        if tops & DEFERRABLE:
            return True
    return False


#: Late imports of light project modules that must stay late, and why.
LATE_ON_PURPOSE = {
    ("agri_training.__main__", "agri_training.cli"): "the numeric kernel pins must be set before numpy is imported",
    ("agri_training", "agri_training.api"): "the numeric kernel pins of `python -m agri_training` must be set before "
    "the package's API (which imports numpy) is loaded",
    ("agri_baselines.hector_slam", "agri_envs.sim2d.gridmap"): "the SLAM algorithm imports no Gymnasium (which "
    "importing agri_envs brings) unless a caller asks for an OccupancyGrid",
}


def test_project_imports_inside_functions_only_defer_heavy_modules():
    """A function may import one of the project's modules late only to defer what that module pulls in."""
    wrong = [
        f"{src}:{line} imports {dst} inside a function"
        for src, out in GRAPH.items()
        for dst, line, inside, _ in out
        if inside and not heavy(dst) and (src, dst) not in LATE_ON_PURPOSE
    ]
    assert not wrong, "\n".join(wrong)


@pytest.mark.parametrize("package", PACKAGES)
def test_function_level_imports_only_defer_heavy_libraries(package):
    wrong = []
    for path in sorted((ROOT / package).rglob("*.py")):
        tree = ast.parse(path.read_text())
        for fn in (n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))):
            for node in ast.walk(fn):
                if isinstance(node, ast.Import):
                    tops = [a.name.split(".")[0] for a in node.names]
                elif isinstance(node, ast.ImportFrom) and not node.level:
                    tops = [(node.module or "").split(".")[0]]
                else:
                    continue
                for top in tops:
                    if top not in DEFERRABLE and top not in PACKAGES:
                        wrong.append(f"{path.relative_to(ROOT)}:{node.lineno} imports {top} inside a function")
    assert not wrong, "\n".join(wrong)
