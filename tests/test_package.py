"""The package's public API: its names, loaded when first used."""

import ast
import importlib
import pathlib
import subprocess
import sys

import pytest

import tid_jax as tj


def test_every_public_name_is_its_modules_object():
    assert tj.__all__ == sorted(tj.__all__) and len(tj.__all__) == len(set(tj.__all__))
    for module, names in tj._API.items():
        for name in names:
            assert getattr(tj, name) is getattr(importlib.import_module(f"tid_jax.{module}"), name)
            assert name in dir(tj)
    assert tj.paper_system().host_mass == 1500.0


def test_an_unknown_name_is_refused_with_its_name():
    with pytest.raises(AttributeError, match="no attribute 'retune_all'"):
        _ = tj.retune_all
    with pytest.raises(ImportError, match="retune_all"):
        exec("from tid_jax import retune_all", {})


def test_importing_the_package_imports_no_jax():
    # What lets the command line start its worker processes before JAX is imported.
    code = ("import sys, tid_jax\n"
            "print(sorted({'jax', 'numpy', 'tid_jax._response'} & set(sys.modules)))")
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True).stdout == "[]\n"


def test_type_checkers_see_every_public_name_as_an_explicit_re_export():
    # `from .module import name as name` under TYPE_CHECKING, as diffrax writes its API:
    # what IDEs and type checkers read, while the names load lazily at run time.
    tree = ast.parse(pathlib.Path(tj.__file__).read_text())
    (block,) = [node for node in tree.body if isinstance(node, ast.If)
                and getattr(node.test, "id", None) == "TYPE_CHECKING"]
    seen = {}
    for node in block.body:
        assert isinstance(node, ast.ImportFrom) and node.level == 1
        for alias in node.names:
            assert alias.asname == alias.name
            seen.setdefault(node.module, set()).add(alias.name)
    assert seen == {module: set(names) for module, names in tj._API.items()}
