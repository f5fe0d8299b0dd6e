"""The examples in the docstrings run and print what they say (doctest)."""

from __future__ import annotations

import doctest
import importlib
import pkgutil

import pytest

import holoprobe


def _modules_with_examples() -> list[str]:
    names = []
    for info in pkgutil.walk_packages(holoprobe.__path__, "holoprobe."):
        if info.name.startswith("holoprobe.cli") or info.name == "holoprobe.__main__":
            continue  # typer commands: examples are shell lines, tested through the CLI
        spec = importlib.util.find_spec(info.name)
        if spec and spec.origin and ">>>" in open(spec.origin, encoding="utf-8").read():
            names.append(info.name)
    return names


MODULES = _modules_with_examples()


def test_the_package_has_examples_to_run():
    assert len(MODULES) >= 10


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples_run(name):
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE,
                             raise_on_error=False, verbose=False)
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples failed in {name}"
