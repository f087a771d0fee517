"""The package layout is the architecture: data flows one way, file -> schema -> graph
-> backend -> result. Every import inside bcad, at module level or inside a function, goes to
the same layer or a lower one, the three families (bayes, worstcase, calibrate) never import
each other, and the module graph has no cycle."""

from __future__ import annotations

import ast

from conftest import REPO

#: lowest first; a module may import its own layer and the layers below it
LAYERS = [
    {
        "bcad.version",
        "bcad.errors",
        "bcad.io",
        "bcad.runtime",
        "bcad.parallel",
        "bcad.worker_env",
        "bcad.tempering",
        "bcad.tables",
        "bcad.arguments",
    },
    {"bcad.numerics"},  # numpy-only numerics: nothing of bcad's above the leaves
    {"bcad.kinematics"},
    {"bcad.relations"},  # the relation kinds: geometry the schema lists and the compiler builds
    {"bcad.model"},
    {"bcad.compiler"},
    {"bcad.bayes", "bcad.worstcase", "bcad.calibration"},
    {"bcad.bayes.document", "bcad.report"},
    {"bcad.api", "bcad.result"},
    {"bcad.batch", "bcad.plot"},
    {"bcad.cli"},
]
FAMILIES = {"bcad.bayes", "bcad.worstcase", "bcad.calibration"}
PACKAGE = REPO / "bcad"


def _module_name(path) -> str:
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


MODULES = {_module_name(path): path for path in PACKAGE.rglob("*.py")}


def _unit(module: str) -> str:
    """The layer unit of a module: its subpackage (bcad.bayes.x -> bcad.bayes) or itself."""
    parts = module.split(".")
    return ".".join(parts[:2])


def _layer(module: str) -> int:
    unit = _unit(module)
    for level, units in enumerate(LAYERS):
        if unit in units:
            return level
    raise AssertionError(f"{module} is in no layer: add its package to LAYERS")


def _imports(module: str) -> set[str]:
    """Every bcad module this one imports (function-level imports too); ``from bcad.x import y``
    counts y when it is a module."""
    tree = ast.parse(MODULES[module].read_text(encoding="utf-8"))
    package = module if MODULES[module].name == "__init__.py" else module.rpartition(".")[0]
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names if alias.name.startswith("bcad"))
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(
                    package.split(".")[: len(package.split(".")) - node.level + 1] + ([base] if base else [])
                )
            if not base.startswith("bcad"):
                continue
            for alias in node.names:
                candidate = f"{base}.{alias.name}"
                found.add(candidate if candidate in MODULES else base)
    return {name for name in found if name in MODULES and name != module}


GRAPH = {module: _imports(module) for module in MODULES if module != "bcad"}


def test_every_module_has_a_layer():
    for module in GRAPH:
        _layer(module)


def test_no_import_goes_up_a_layer():
    upward = [
        f"{module} -> {target}"
        for module, targets in GRAPH.items()
        for target in targets
        if target != "bcad" and _layer(target) > _layer(module)
    ]
    assert not upward, upward


def test_nothing_inside_the_package_imports_the_package_root():
    """``from bcad import __version__`` closed a cycle through the lazy API (bcad/__init__ -> api)."""
    offenders = [module for module, targets in GRAPH.items() if "bcad" in targets]
    assert not offenders, offenders


def test_the_families_do_not_import_each_other():
    crossing = [
        f"{module} -> {target}"
        for module, targets in GRAPH.items()
        for target in targets
        if _unit(module) in FAMILIES and _unit(target) in FAMILIES and _unit(module) != _unit(target)
    ]
    assert not crossing, crossing


def test_the_module_graph_has_no_cycle():
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(module: str) -> None:
        state[module] = 1
        stack.append(module)
        for target in sorted(GRAPH.get(module, ())):
            if state.get(target) == 1:
                raise AssertionError("import cycle: " + " -> ".join(stack[stack.index(target) :] + [target]))
            if target not in state:
                visit(target)
        stack.pop()
        state[module] = 2

    for module in sorted(GRAPH):
        if module not in state:
            visit(module)


def test_the_checker_sees_an_upward_import(tmp_path):
    """The checker itself: a lower module importing a higher one is caught."""
    assert _layer("bcad.kinematics.chain") < _layer("bcad.api")
    assert _unit("bcad.bayes.objective") == "bcad.bayes"


def test_the_api_is_a_thin_facade():
    """The families own their runs and checks: the API module only calls and composes them."""
    lines = (PACKAGE / "api.py").read_text(encoding="utf-8").splitlines()
    assert len(lines) < 200, len(lines)
