"""The package's structure: no module imports another sub-package's private module.

The layer order itself is checked by import-linter (``make lint``, pyproject.toml).
"""

from __future__ import annotations

import ast
from pathlib import Path

import holoprobe

SRC = Path(holoprobe.__file__).parent


def _imported_modules(path: Path) -> list[str]:
    names = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.append(node.module)
            names += [f"{node.module}.{a.name}" for a in node.names]
        elif isinstance(node, ast.Import):
            names += [a.name for a in node.names]
    return names


def _private_of_other_package(importer: str, imported: str) -> bool:
    parts = imported.split(".")
    for i, part in enumerate(parts[1:], start=1):
        if part.startswith("_") and not part.startswith("__"):
            owner = ".".join(parts[:i])  # the package whose private module this is
            return owner != "holoprobe" and not importer.startswith(owner + ".")
    return False


def test_no_module_imports_a_private_module_of_another_package():
    offenders = []
    for path in sorted(SRC.rglob("*.py")):
        module = ".".join(path.relative_to(SRC.parent).with_suffix("").parts)
        for name in _imported_modules(path):
            if name.startswith("holoprobe.") and _private_of_other_package(module, name):
                offenders.append(f"{module} imports {name}")
    assert offenders == []


def test_the_private_module_rule_flags_what_it_should():
    assert _private_of_other_package("holoprobe.simulate._array",
                                     "holoprobe.characterize._lens")
    assert not _private_of_other_package("holoprobe.characterize._pipeline",
                                         "holoprobe.characterize._lens")
    assert not _private_of_other_package("holoprobe.propagation._rayleigh",
                                         "holoprobe._numba")
