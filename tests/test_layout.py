"""The package's layout stays light: no module over `MAX_MODULE_LINES` lines, no function
or method whose body (without its docstring) is over `MAX_BODY_LINES` lines."""

import ast
import pathlib
import re

import pytest

PACKAGE = pathlib.Path(__file__).resolve().parents[1] / "tid_jax"
MODULES = sorted(PACKAGE.rglob("*.py"))
MAX_MODULE_LINES = 600
MAX_BODY_LINES = 80


def _body_lines(function: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    """The lines of `function`'s body, from its first statement after the docstring to
    the end of its last (nested functions and classes included)."""
    body = function.body
    if (len(body) > 1 and isinstance(body[0], ast.Expr)
            and isinstance(body[0].value, ast.Constant) and isinstance(body[0].value.value, str)):
        body = body[1:]
    return body[-1].end_lineno - body[0].lineno + 1


def _functions(source: str) -> list:
    """Every function and method of the module `source`, nested ones included."""
    return [node for node in ast.walk(ast.parse(source))
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)]


def _name(path: pathlib.Path) -> str:
    return str(path.relative_to(PACKAGE.parent))


def test_the_modules_are_found():
    names = [_name(path) for path in MODULES]
    assert "tid_jax/__init__.py" in names and "tid_jax/cli/_main.py" in names


def test_no_module_is_over_600_lines():
    long = [f"{_name(path)} ({lines} lines)" for path in MODULES
            if (lines := len(path.read_text().splitlines())) > MAX_MODULE_LINES]
    assert not long, f"modules over {MAX_MODULE_LINES} lines: {', '.join(long)}"


def test_no_function_body_is_over_80_lines():
    long = [f"{_name(path)}:{function.lineno} {function.name} ({lines} lines)"
            for path in MODULES for function in _functions(path.read_text())
            if (lines := _body_lines(function)) > MAX_BODY_LINES]
    assert not long, f"function bodies over {MAX_BODY_LINES} lines: {', '.join(long)}"


def test_a_body_is_counted_without_its_docstring():
    source = 'def f():\n    """Doc\n    string."""\n    x = 1\n\n    return x\n'
    (function,) = _functions(source)
    assert _body_lines(function) == 3
    (only_docstring,) = _functions('def g():\n    """Only a docstring."""\n')
    assert _body_lines(only_docstring) == 1



@pytest.mark.parametrize("name", ["README.md", "benchmarks/README.md"])
def test_the_readmes_are_at_most_250_lines_and_hold_no_dates(name):
    # Documents for users: the latest measurements only, no run-by-run history.
    text = (PACKAGE.parent / name).read_text()
    assert len(text.splitlines()) <= 250
    dated = re.findall(r"\b20[0-9]{2}-[01][0-9]-[0-3][0-9]\b", text)
    assert not dated, f"{name} names dates: {dated}"
