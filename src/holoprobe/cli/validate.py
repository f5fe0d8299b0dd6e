"""``holoprobe validate``: compare the virtual transducer's field with a measured one.

A thin shell over :func:`holoprobe.exposure.validate_field` and
:func:`holoprobe.exposure.plot_validation` (paper section III C). The measured-field
file format is described in ``docs/validation.md``.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from holoprobe.cli._app import OutputDirectory, TransmitSetting, VirtualTransducerPath

__all__ = ["validate"]


def validate(
    virtual_transducer: VirtualTransducerPath,
    transmit: TransmitSetting,
    measured: Annotated[Path, typer.Option(
        "--measured", help="Measured field (HDF5, format holoprobe-measured-field).")],
    out: OutputDirectory,
    band_threshold_db: Annotated[float, typer.Option(
        help="Energy threshold of the propagated band in dB.")] = -40.0,
    overwrite: Annotated[bool, typer.Option(help="Replace existing outputs.")] = False,
) -> None:
    """Best scale factor, normalised error and on-axis profiles vs a measured field."""
    from rich.console import Console
    from rich.table import Table

    from holoprobe.exposure import plot_validation, validate_field
    from holoprobe.io import atomic_write
    from holoprobe.transducer import TransmitSetting, VirtualTransducer

    vt = VirtualTransducer.load(virtual_transducer)
    setting = TransmitSetting.from_toml(transmit)
    result = validate_field(vt, setting, measured, band_threshold_db=band_threshold_db)
    out.mkdir(parents=True, exist_ok=True)
    summary = result.to_dict()
    summary.update({"virtual_transducer": str(virtual_transducer), "transmit": str(transmit),
                    "measured": str(measured)})
    with atomic_write(out / "validation.json", overwrite=overwrite,
                      protect=[virtual_transducer, transmit, measured]) as tmp:
        tmp.write_text(json.dumps(summary, indent=2))
    plot_validation(result, out / "validation_profiles.png", overwrite=overwrite)
    table = Table(title="validation against the measured field")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    table.add_row("scale factor Σxy/Σy²", f"{result.scale:.4f}")
    table.add_row("normalised error", f"{100 * result.normalised_error:.2f} %")
    table.add_row("largest sample error", f"{100 * result.peak_error:.2f} % of max |p|")
    table.add_row("profile", f"along {result.profile_axis}")
    Console().print(table)
