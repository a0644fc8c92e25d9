"""The core's import graph has no cycle, function-level (lazy) imports included: a module that
needs another imports it, never the other way round as well (``typing.TYPE_CHECKING`` imports
do not run and do not count)."""

import ast
from pathlib import Path

CORE = Path(__file__).resolve().parents[2] / "agndc_core"


def module_imports() -> dict[str, set[str]]:
    """{module: the core modules it imports anywhere in its code}."""
    modules = {}
    for path in CORE.rglob("*.py"):
        parts = path.relative_to(CORE.parent).with_suffix("").parts
        modules[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    graph = {}
    for name, path in modules.items():
        tree = ast.parse(path.read_text())
        package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
        skipped = {id(node) for block in ast.walk(tree) if isinstance(block, ast.If)
                   and getattr(block.test, "id", "") == "TYPE_CHECKING"
                   for node in ast.walk(block)}
        targets = set()
        for node in ast.walk(tree):
            if id(node) in skipped:
                continue
            if isinstance(node, ast.ImportFrom):
                base = package.split(".")[:len(package.split(".")) - node.level + 1] \
                    if node.level else []
                target = ".".join(base + ([node.module] if node.module else []))
                targets |= {target, *(f"{target}.{alias.name}" for alias in node.names)}
            elif isinstance(node, ast.Import):
                targets |= {alias.name for alias in node.names}
        # the package itself only re-exports lazily (agndc_core.__getattr__)
        graph[name] = {t for t in targets if t in modules and t not in (name, "agndc_core")}
    return graph


def test_the_core_import_graph_has_no_cycle():
    graph = module_imports()
    assert len(graph) > 50 and "agndc_core.pipeline" in graph["agndc_core.cli"]
    state, cycles = {}, []

    def visit(module, path):
        state[module] = "open"
        for other in sorted(graph[module]):
            if state.get(other) == "open":
                cycles.append(path[path.index(other):] + [module, other])
            elif other not in state:
                visit(other, path + [module])
        state[module] = "done"

    for module in sorted(graph):
        if module not in state:
            visit(module, [])
    assert not cycles, cycles
