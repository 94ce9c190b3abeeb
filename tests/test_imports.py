"""The package's imports: they run one way (a DAG, function-level imports included), as
docs/architecture.md draws them, and reach other libraries through their public APIs
only."""

import ast
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "tid_jax"
# Libraries whose private modules (a `_`-prefixed part, `_src`) must never be imported.
LIBRARIES = ("jax", "jaxlib", "equinox", "diffrax", "optimistix", "lineax", "jaxtyping")


def _module_name(path: pathlib.Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {_module_name(path): path for path in sorted(PACKAGE.rglob("*.py"))}


def _imports(name: str, path: pathlib.Path) -> list[tuple[str, int]]:
    """Every module named by an import statement anywhere in the file (functions
    included), absolute, with its line."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found += [(alias.name, node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module
            # `from . import name` names a module where there is one, else a name of
            # the module `module`
            submodules = [f"{module}.{alias.name}" for alias in node.names
                          if f"{module}.{alias.name}" in MODULES]
            found += [(name, node.lineno) for name in submodules]
            if len(submodules) < len(node.names):
                found.append((module, node.lineno))
    return found


def _graph() -> dict[str, set[str]]:
    return {name: {module for module, _ in _imports(name, path)
                   if module in MODULES and module != name}
            for name, path in MODULES.items()}


def test_the_graph_is_built_from_every_module_and_function_level_imports():
    graph = _graph()
    assert len(graph) >= 20
    # a function-level import of the package's own module is an edge
    assert "tid_jax.cli._main" in graph["tid_jax.cli"]
    assert "tid_jax._runtime._cache" in graph["tid_jax._runtime._parallel"]


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """A cycle of `graph` (a list of nodes, the first repeated at the end), or None."""
    state: dict[str, str] = {}
    stack: list[str] = []

    def visit(node):
        state[node] = "open"
        stack.append(node)
        for child in sorted(graph.get(node, ())):
            if state.get(child) == "open":
                return stack[stack.index(child):] + [child]
            if child not in state and (found := visit(child)):
                return found
        stack.pop()
        state[node] = "done"
        return None

    for node in sorted(graph):
        if node not in state and (found := visit(node)):
            return found
    return None


def test_a_cycle_is_found():
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b", "c"}, "b": {"c"}, "c": set()}) is None


def test_imports_form_a_dag():
    cycle = _cycle(_graph())
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


@pytest.mark.parametrize("name", sorted(MODULES))
def test_no_private_module_of_another_library_is_imported(name):
    private = [
        f"{module} (line {line})" for module, line in _imports(name, MODULES[name])
        if module.split(".")[0] in LIBRARIES
        and any(part.startswith("_") for part in module.split(".")[1:])
    ]
    assert not private, f"{name} imports private modules: {', '.join(private)}"


@pytest.mark.parametrize("name", sorted(MODULES))
def test_no_attribute_of_another_library_is_assigned(name):
    tree = ast.parse(MODULES[name].read_text())
    aliases = {alias.asname or alias.name.split(".")[0]
               for node in ast.walk(tree) if isinstance(node, ast.Import)
               for alias in node.names if alias.name.split(".")[0] in LIBRARIES}
    assigned = [
        f"line {node.lineno}" for node in ast.walk(tree)
        if isinstance(node, (ast.Assign, ast.AugAssign, ast.AnnAssign))
        for target in (node.targets if isinstance(node, ast.Assign) else [node.target])
        if isinstance(target, ast.Attribute)
        and isinstance(root := _root(target), ast.Name) and root.id in aliases
    ]
    assert not assigned, f"{name} assigns attributes of other libraries: {assigned}"


def _root(node):
    while isinstance(node, ast.Attribute):
        node = node.value
    return node


def test_the_architecture_page_draws_the_graph():
    # Its table lists every module with the package's modules it imports, each row
    # below the rows of those it imports.
    text = (ROOT / "docs" / "architecture.md").read_text()
    section = text.split("\n## Modules and their imports\n", 1)[1].split("\n## ", 1)[0]
    rows = [line.split("|")[1:-1] for line in section.splitlines()
            if line.startswith("| `")]
    full = lambda cell: "tid_jax" if cell == "tid_jax" else f"tid_jax.{cell}"
    drawn = {full(name.strip().strip("`")): {full(part.strip().strip("`"))
                                             for part in imports.split(",") if part.strip()}
             for name, _, imports in rows}
    assert drawn == _graph()
    order = [full(name.strip().strip("`")) for name, _, _ in rows]
    for i, name in enumerate(order):
        assert drawn[name] <= set(order[:i]), f"{name} is drawn above a module it imports"
