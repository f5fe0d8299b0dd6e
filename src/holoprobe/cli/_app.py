"""The settings every ``holoprobe`` Typer app shares (the root and its sub-apps)."""

from __future__ import annotations

from typing import Any

import typer

__all__ = ["new_app"]


def new_app(help: str, **kwargs: Any) -> typer.Typer:
    """A Typer app that shows its help when called without arguments, installs no
    shell completion and prints plain (not rich) tracebacks.

    Parameters
    ----------
    help : str
        The app's help text.
    **kwargs
        Further :class:`typer.Typer` arguments (e.g. ``name``).

    Returns
    -------
    typer.Typer
    """
    return typer.Typer(help=help, no_args_is_help=True, add_completion=False,
                       pretty_exceptions_enable=False, **kwargs)
