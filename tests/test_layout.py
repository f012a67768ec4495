"""The package's layout: one subpackage per stage, imports only downward, no cycles.

Imports are read from the source (every ``import``/``from`` statement,
module-level or inside functions), so a lazy import cannot hide an upward
dependency or a cycle.
"""

import ast
import pathlib

import pytest

import leaps_mj

PACKAGE = pathlib.Path(leaps_mj.__file__).parent
#: Stages from the bottom up: a module may import its own stage and those below.
STAGES = ("world", "environment", "records", "planning", "learning", "evaluation")
#: Modules at the package top: command entry points and the gymnasium id's module, above every stage.
TOP = {"leaps_mj", "leaps_mj.train", "leaps_mj.evaluate", "leaps_mj.replay", "leaps_mj.gym_adapter"}
MAX_LINES = 700


def _module_name(path: pathlib.Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _modules() -> dict[str, pathlib.Path]:
    return {_module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def _imports(name: str, path: pathlib.Path, known: set[str]) -> set[str]:
    """Package modules that ``name`` imports."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            targets = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
        else:
            continue
        out |= {t for t in targets if t in known and t != name}
    return out


def _graph() -> dict[str, set[str]]:
    modules = _modules()
    return {name: _imports(name, path, set(modules)) for name, path in modules.items()}


def _stage(name: str) -> int | None:
    parts = name.split(".")
    return STAGES.index(parts[1]) if len(parts) > 1 and parts[1] in STAGES else None


def test_every_module_belongs_to_a_stage_or_the_top():
    stray = [m for m in _modules() if m not in TOP and _stage(m) is None]
    assert not stray, f"modules outside the stage subpackages {STAGES}: {stray}"


def test_stages_import_only_downward():
    upward = [(m, d) for m, deps in _graph().items() if _stage(m) is not None
              for d in deps if d in TOP or (_stage(d) is not None and _stage(d) > _stage(m))]
    assert not upward, f"imports of a higher stage (stages bottom-up: {STAGES}): {upward}"


def test_no_import_cycles():
    graph, state, cycles = _graph(), {}, []

    def visit(m, stack):
        state[m] = "open"
        for d in sorted(graph[m]):
            if d.startswith(m + ".") or m.startswith(d + "."):
                continue  # a package and its own modules
            if state.get(d) == "open":
                cycles.append(stack[stack.index(d):] + [d])
            elif d not in state:
                visit(d, stack + [d])
        state[m] = "done"

    for m in sorted(graph):
        if m not in state:
            visit(m, [m])
    assert not cycles, f"import cycles: {cycles}"


@pytest.mark.parametrize("name", sorted(_modules()))
def test_modules_stay_small(name):
    lines = len(_modules()[name].read_text().splitlines())
    assert lines <= MAX_LINES, f"{name} has {lines} lines; split it (limit {MAX_LINES})"


def test_stage_packages_say_what_they_own():
    for stage in STAGES:
        doc = ast.get_docstring(ast.parse((PACKAGE / stage / "__init__.py").read_text()))
        assert doc and len(doc.split()) > 15, f"leaps_mj.{stage} needs a docstring saying what it owns"
