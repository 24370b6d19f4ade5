"""The house rule of docs/design.md, checked on every `import` in src/zodrive (inside functions too):
a module imports only from rooms on lower floors (or its own room), and no modules import in a circle."""

from __future__ import annotations

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"

#: floors from the bottom; rooms on one floor may not import each other
FLOORS: list[tuple[str, ...]] = [
    ("errors", "seeds", "compute", "runinfo", "config", "validation", "signing"),  # the base: may import each other
    ("attacks", "envs"),
    ("drivers",),
    ("policies", "defense"),
    ("system",),
    ("evaluation",),
    ("training",),
    ("experiments",),
    ("bench",),  # the bench and the leaderboard, on the grid engine and card writer of experiments/
    ("api",),
    ("cli",),
    ("__main__", ""),  # "" is the package's own __init__ (its public names, read lazily)
]
FLOOR = {room: level for level, rooms in enumerate(FLOORS) for room in rooms}


def module_name(path: Path) -> str:
    parts = list(path.relative_to(SRC).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports(path: Path) -> set[str]:
    """The zodrive modules `path` imports, resolved to module names (`from a import b` counts
    `a.b` when that is a module)."""
    name = module_name(path)
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom):
            base = ".".join(package[: len(package) - node.level + 1] + ([node.module] if node.module else [])) \
                if node.level else (node.module or "")
            if base == "zodrive" or base.startswith("zodrive."):
                for alias in node.names:
                    sub = f"{base}.{alias.name}"
                    found.add(sub if _exists(sub) else base)
        elif isinstance(node, ast.Import):
            found.update(a.name for a in node.names if a.name == "zodrive" or a.name.startswith("zodrive."))
    return found


def _exists(module: str) -> bool:
    rel = Path(*module.split("."))
    return (SRC / rel).with_suffix(".py").is_file() or (SRC / rel / "__init__.py").is_file()


def room(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def graph() -> dict[str, set[str]]:
    return {module_name(p): imports(p) for p in sorted((SRC / "zodrive").rglob("*.py"))}


def test_every_room_is_on_a_floor() -> None:
    assert {room(m) for m in graph()} <= set(FLOOR)


def test_no_import_runs_upward_or_sideways() -> None:
    wrong = []
    for module, deps in graph().items():
        for dep in deps:
            here, there = room(module), room(dep)
            if here != there and (FLOOR[there] > FLOOR[here] or FLOOR[there] == FLOOR[here] > 0):
                wrong.append(f"{module} -> {dep}")
    assert wrong == []


def test_no_circle() -> None:
    edges = graph()
    state: dict[str, int] = {}
    circles: list[list[str]] = []

    def visit(node: str, path: list[str]) -> None:
        state[node] = 1
        for dep in sorted(edges.get(node, ())):
            if dep not in edges or dep == node:
                continue
            if state.get(dep) == 1:
                circles.append(path[path.index(dep):] + [dep] if dep in path else [node, dep])
            elif dep not in state:
                visit(dep, path + [dep])
        state[node] = 2

    for node in edges:
        if node not in state:
            visit(node, [node])
    assert circles == []


def test_the_check_sees_an_upward_import(tmp_path: Path) -> None:
    """The reader finds imports inside functions and relative ones, so the rule can fail."""
    file = SRC / "zodrive" / "attacks" / "__probe__.py"
    try:
        file.write_text("def f():\n    from ..evaluation import rollout\n    from zodrive.cli import main\n")
        assert imports(file) == {"zodrive.evaluation.rollout", "zodrive.cli"}
    finally:
        file.unlink()
