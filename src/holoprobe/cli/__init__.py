"""The ``holoprobe`` command: a thin shell over functions you can also call from Python.

Each sub-command lives in its own module of this package and is registered here.
Errors a user causes (:class:`holoprobe.InputError`) are printed on one line and
exit with status 2.
"""

from __future__ import annotations

import importlib
import sys

import typer

from holoprobe.cli._app import new_app
from holoprobe.errors import HoloprobeError

app = new_app(
    "Acoustic holography of ultrasound transducers: scan + echo -> virtual transducer.",
    name="holoprobe",
)


@app.callback()
def _root() -> None:
    """holoprobe: characterize an ultrasound transducer from a hydrophone scan."""


# (module, attribute, name): sub-apps (typer.Typer) or commands (functions).
_SUBAPPS = [
    ("holoprobe.cli.simulate", "app", "simulate"),
    ("holoprobe.cli.analyse", "app", "analyse"),
    ("holoprobe.cli.export", "app", "export"),
    ("holoprobe.cli.hydrophone", "app", "hydrophone"),
]
_COMMANDS: list[tuple[str, str, str]] = [
    ("holoprobe.cli.characterize", "characterize", "characterize"),
    ("holoprobe.cli.field", "field", "field"),
    ("holoprobe.cli.rf", "rf", "rf"),
    ("holoprobe.cli.output", "output", "output"),
    ("holoprobe.cli.validate", "validate", "validate"),
]

for _module, _attr, _name in _SUBAPPS:
    app.add_typer(getattr(importlib.import_module(_module), _attr), name=_name)

for _module, _attr, _name in _COMMANDS:
    app.command(name=_name)(getattr(importlib.import_module(_module), _attr))


@app.command()
def version() -> None:
    """Print the holoprobe version."""
    from holoprobe import __version__

    typer.echo(__version__)


def main() -> None:
    """Entry point: run the app, turning :class:`InputError` into a one-line error."""
    try:
        app()
    except HoloprobeError as exc:  # InputError or FitError: one line, exit 2
        typer.secho(f"error: {exc}", err=True, fg=typer.colors.RED)
        sys.exit(2)
