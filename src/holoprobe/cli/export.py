"""``holoprobe export``: write a virtual transducer for other simulators.

* ``holoprobe export proteus VT.h5 --out DIR``: ``Transducer.mat``, ``IR_transmit.mat``,
  ``IR_receive.mat`` (:func:`holoprobe.export.export_proteus`).
* ``holoprobe export kwave VT.h5 --transmit TX.toml --grid NX NY NZ --spacing-mm D
  --dt-ns DT --nt NT --out FILE.h5``: an on-grid (staircase) source mask and its
  signals for k-Wave / k-wave-python (:func:`holoprobe.export.kwave_grid_source`),
  without needing k-wave-python. For off-grid sources use
  :func:`holoprobe.export.kwave_source` from Python (``docs/kwave.md``).
* ``holoprobe export uff VT.h5 --out PROBE.uff``: UFF v0.3 probe
  (:func:`holoprobe.export.export_uff`).
* ``holoprobe export verasonics VT.h5 --out TRANS.mat``: Verasonics ``Trans`` struct
  (:func:`holoprobe.export.export_verasonics`).
* ``holoprobe export pymust VT.h5 --out PARAM.json``: PyMUST ``param``
  (:func:`holoprobe.export.pymust_param`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from holoprobe.cli._app import OutputDirectory, TransmitSetting, VirtualTransducerPath, new_app

app = new_app("Export a virtual transducer to PROTEUS, k-Wave, UFF, Verasonics or PyMUST.")


@app.command()
def proteus(
    virtual_transducer: VirtualTransducerPath,
    out: OutputDirectory,
    overwrite: Annotated[bool, typer.Option(help="Replace existing files.")] = False,
) -> None:
    """PROTEUS Transducer struct and IR files (250 MHz)."""
    from holoprobe.export import export_proteus
    from holoprobe.transducer import VirtualTransducer

    files = export_proteus(VirtualTransducer.load(virtual_transducer), out,
                           overwrite=overwrite)
    for path in files.values():
        typer.echo(str(path))


@app.command()
def kwave(
    virtual_transducer: VirtualTransducerPath,
    transmit: TransmitSetting,
    grid: Annotated[tuple[int, int, int], typer.Option(
        "--grid", help="Grid size Nx Ny Nz (x propagation, y lateral, z elevation).")],
    spacing_mm: Annotated[float, typer.Option("--spacing-mm", help="Grid step in mm.")],
    dt_ns: Annotated[float, typer.Option("--dt-ns", help="Time step in ns.")],
    nt: Annotated[int, typer.Option("--nt", help="Number of time steps.")],
    out: Annotated[Path, typer.Option("--out", help="Output HDF5 file.")],
    representation: Annotated[str, typer.Option(
        help="monopole (source.p = ρ0c0·u) or dipole (source.ux = u).")] = "monopole",
    source_x_mm: Annotated[float | None, typer.Option(
        help="x of the array face in mm (k-Wave coordinates; default grid plane 1).")] = None,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing file.")] = False,
) -> None:
    """On-grid k-Wave source: mask (Nx, Ny, Nz) and signals (points, nt) in HDF5."""
    from holoprobe.errors import InputError
    from holoprobe.export import kwave_grid_source
    from holoprobe.io import write_kwave_source
    from holoprobe.transducer import TransmitSetting, VirtualTransducer

    if not (spacing_mm > 0 and dt_ns > 0):
        raise InputError("expected a positive grid step and time step", field="--spacing-mm")
    vt = VirtualTransducer.load(virtual_transducer)
    setting = TransmitSetting.from_toml(transmit)
    d = spacing_mm * 1e-3
    mask, signals = kwave_grid_source(
        vt, setting, grid, (d, d, d), dt_ns * 1e-9, nt, representation=representation,
        source_x=None if source_x_mm is None else source_x_mm * 1e-3)
    write_kwave_source(out, mask, signals, representation=representation, spacing=d,
                       dt=dt_ns * 1e-9, overwrite=overwrite,
                       protect=[virtual_transducer, transmit])
    typer.echo(str(out))



@app.command()
def uff(
    virtual_transducer: VirtualTransducerPath,
    out: Annotated[Path, typer.Option("--out", help="Output UFF (HDF5) file.")],
    overwrite: Annotated[bool, typer.Option(help="Replace an existing file.")] = False,
) -> None:
    """UFF v0.3 probe: element geometry, impulse responses, elevation focal length."""
    from holoprobe.export import export_uff
    from holoprobe.transducer import VirtualTransducer

    typer.echo(str(export_uff(VirtualTransducer.load(virtual_transducer), out,
                              overwrite=overwrite)))


@app.command()
def verasonics(
    virtual_transducer: VirtualTransducerPath,
    out: Annotated[Path, typer.Option("--out", help="Output .mat file (Trans struct).")],
    sound_speed: Annotated[float, typer.Option(
        help="Verasonics speed of sound (m/s) that defines the wavelength.")] = 1540.0,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing file.")] = False,
) -> None:
    """Verasonics Trans struct (.mat, units wavelengths; IR1wy/IR2wy at 250 MHz)."""
    from holoprobe.export import export_verasonics
    from holoprobe.transducer import VirtualTransducer

    typer.echo(str(export_verasonics(VirtualTransducer.load(virtual_transducer), out,
                                     sound_speed=sound_speed, overwrite=overwrite)))


@app.command()
def pymust(
    virtual_transducer: VirtualTransducerPath,
    out: Annotated[Path, typer.Option("--out", help="Output JSON file (the param dict).")],
    baffle: Annotated[str, typer.Option(help="rigid, soft or a positive number.")] = "rigid",
    overwrite: Annotated[bool, typer.Option(help="Replace an existing file.")] = False,
) -> None:
    """PyMUST param (JSON): Nelements, fc, pitch, width, kerf, height, focus, bandwidth."""
    from holoprobe.errors import InputError
    from holoprobe.export import pymust_param
    from holoprobe.io import write_json
    from holoprobe.transducer import VirtualTransducer

    try:
        value: str | float = baffle if baffle in ("rigid", "soft") else float(baffle)
    except ValueError:
        raise InputError(f"expected rigid, soft or a number, got {baffle!r}",
                         field="--baffle") from None
    param = pymust_param(VirtualTransducer.load(virtual_transducer), baffle=value)
    param["note"] = "MUST synthesises its pulse from fc and bandwidth only"
    typer.echo(str(write_json(out, param, overwrite=overwrite,
                              protect=(virtual_transducer,))))
