"""The package import graph has no cycles and the backend imports nothing above it.

Packages are the top-level folders (``renderers``, ``data_gen``, ``evaluation``) and the first-level
packages of ``paz6d`` (``paz6d.backend``, ``paz6d.aae``, ...). Every import counts, including those
inside functions, so a cycle cannot hide behind a deferred import.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TOP_LEVEL = ("paz6d", "renderers", "data_gen", "evaluation")


def package_of(module: str) -> str:
    parts = module.split(".")
    return ".".join(parts[:2]) if parts[0] == "paz6d" and len(parts) > 1 else parts[0]


def imported_modules(tree: ast.AST) -> list[str]:
    names = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.append(node.module)
        elif isinstance(node, ast.Import):
            names.extend(alias.name for alias in node.names)
    return [name for name in names if name.split(".")[0] in TOP_LEVEL]


def package_graph() -> dict[str, set[str]]:
    graph: dict[str, set[str]] = {}
    for top in TOP_LEVEL:
        for path in (ROOT / top).rglob("*.py"):
            module = ".".join(path.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")
            source = package_of(module)
            targets = graph.setdefault(source, set())
            for name in imported_modules(ast.parse(path.read_text(encoding="utf-8"))):
                target = package_of(name)
                if target not in (source, "paz6d"):
                    targets.add(target)
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle as a list of packages (first == last), or None; depth-first search."""
    state: dict[str, int] = {}
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for target in sorted(graph.get(node, ())):
            if state.get(target) == 1:
                return path[path.index(target):] + [target]
            if target not in state and (cycle := visit(target)):
                return cycle
        state[node] = 2
        path.pop()
        return None

    for node in sorted(graph):
        if node not in state and (cycle := visit(node)):
            return cycle
    return None


def test_find_cycle_detects_a_planted_cycle():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None


def test_no_import_cycle_between_packages():
    cycle = find_cycle(package_graph())
    assert cycle is None, f"import cycle between packages: {' -> '.join(cycle)}"


def test_backend_imports_nothing_above_it():
    assert package_graph()["paz6d.backend"] == set()


def module_graph() -> dict[str, set[str]]:
    """Module -> the project modules it imports (``from package import module`` resolved)."""
    paths = {".".join(path.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__"): path
             for top in TOP_LEVEL for path in (ROOT / top).rglob("*.py")}
    graph: dict[str, set[str]] = {}
    for module, path in paths.items():
        targets = graph.setdefault(module, set())
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                candidates = [f"{node.module}.{alias.name}" for alias in node.names] + [node.module]
            elif isinstance(node, ast.Import):
                candidates = [alias.name for alias in node.names]
            else:
                continue
            for name in candidates:
                if name in paths and name != module:
                    targets.add(name)
                    break
    return graph


def test_no_import_cycle_between_modules():
    cycle = find_cycle(module_graph())
    assert cycle is None, f"import cycle between modules: {' -> '.join(cycle)}"


#: What is worth keeping out of a process that does not need it (import time, memory, or TensorFlow and
#: GL apart): third-party libraries (optional ones included) and the project's doors to TF and GL.
#: Only the standard library, numpy and project modules that reach none of these are "light".
HEAVY_PROJECT_MODULES = {"renderers", "paz6d.backend.tensorflow_guard"}
LIGHT_THIRD_PARTY = {"numpy"}


def module_imports(path: Path, top_level_only: bool) -> list[tuple[int, str]]:
    """``(line, module)`` of the imports in a file: only those at module level, or only those inside
    functions. Names imported by one statement share its line."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    inner = {id(node) for function in ast.walk(tree) if isinstance(function, (ast.FunctionDef, ast.AsyncFunctionDef))
             for node in ast.walk(function) if isinstance(node, (ast.Import, ast.ImportFrom))}
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, (ast.Import, ast.ImportFrom)) or (id(node) in inner) == top_level_only:
            continue
        if isinstance(node, ast.ImportFrom):
            if node.module and node.level == 0:
                found += [(node.lineno, f"{node.module}.{alias.name}") for alias in node.names]
        else:
            found += [(node.lineno, alias.name) for alias in node.names]
    return found


def loads_heavy_library(module: str, paths: dict[str, Path], seen: set[str]) -> bool:
    """Whether importing ``module`` loads a third-party library other than numpy, TensorFlow or GL,
    following module-level imports."""
    top = module.split(".")[0]
    if module in HEAVY_PROJECT_MODULES or top in HEAVY_PROJECT_MODULES:
        return True
    if top not in TOP_LEVEL:
        return top not in sys.stdlib_module_names and top not in LIGHT_THIRD_PARTY
    if module not in paths:
        parent = module.rpartition(".")[0]  # `from package import name` where name is not a module
        return bool(parent) and loads_heavy_library(parent, paths, seen)
    if module in seen:
        return False
    seen.add(module)
    parts = module.split(".")
    packages = [".".join(parts[:end]) for end in range(1, len(parts))]  # parents run their __init__ first
    return any(loads_heavy_library(name, paths, seen)
               for name in packages + [name for _, name in module_imports(paths[module], top_level_only=True)])


def test_imports_inside_functions_only_defer_heavy_libraries():
    paths = {".".join(path.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__"): path
             for top in TOP_LEVEL for path in (ROOT / top).rglob("*.py")}
    needless = []
    for path in paths.values():
        statements: dict[int, list[str]] = {}
        for line, name in module_imports(path, top_level_only=False):
            statements.setdefault(line, []).append(name)
        needless += [f"{path.relative_to(ROOT)}:{line} {', '.join(names)}" for line, names in statements.items()
                     if not any(loads_heavy_library(name, paths, set()) for name in names)]
    assert not needless, ("imports inside functions that defer nothing heavy (move them to the top):\n"
                          + "\n".join(needless))
