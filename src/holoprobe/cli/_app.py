"""The settings every ``holoprobe`` Typer app shares (the root and its sub-apps)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

__all__ = ["OutputDirectory", "TransmitSetting", "VirtualTransducerPath", "new_app"]


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


VirtualTransducerPath = Annotated[Path, typer.Argument(help="virtual_transducer.h5")]
"""The positional ``virtual_transducer.h5`` argument of the commands that use one."""
OutputDirectory = Annotated[Path, typer.Option("--out", help="Output directory.")]
"""The ``--out`` option of the commands that write a directory."""
TransmitSetting = Annotated[Path, typer.Option("--transmit", help="Transmit setting (TOML).")]
"""The ``--transmit`` option: a transmit setting file (TOML)."""
