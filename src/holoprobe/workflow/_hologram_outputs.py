"""Files of one hologram characterization: summary.json, source.h5, focal_volume.h5
(focused sources), report.html.

(The run assembly for the CLI and notebooks; it moves to ``holoprobe.workflow`` once that
layer exists.)
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from holoprobe.characterize import HologramResult, hologram_summary
from holoprobe.errors import InputError
from holoprobe.io import SourceVelocity, write_focal_volume, write_json, write_source

__all__ = ["HOLOGRAM_OUTPUT_FILES", "hologram_report_figures", "source_velocity",
           "write_hologram_outputs"]

HOLOGRAM_OUTPUT_FILES = ("summary.json", "source.h5", "focal_volume.h5", "report.html")


def source_velocity(result: HologramResult) -> SourceVelocity:
    """The reconstructed source as a :class:`holoprobe.io.SourceVelocity` (scan coordinates).

    CW holograms: the velocity amplitude at the hologram's frequency; transient ones: the
    velocity spectra on the bins of the (shortened, ``result.band_decimation``) record that
    holds the source's pulse (per-point waveforms by ``.waveforms()``).
    """
    rec = result.reconstruction
    g = rec.geometry
    common: dict[str, Any] = dict(
        surface=rec.unrolled.surface, medium=result.hologram.medium, kind=g.kind,
        radius_of_curvature=g.radius_of_curvature, aperture=g.aperture, apex=g.apex,
        axis=g.axis, coordinates="scan")
    if result.band_velocity is not None and result.velocity_band is not None:
        # the bins of a record of velocity_record samples
        h = result.hologram
        assert result.velocity_band is not None  # set with band_velocity (transient)
        return SourceVelocity(frequencies=result.velocity_band, velocity=result.band_velocity,
                              spectral=True, sampling_rate=h.sampling_rate,
                              n_time=result.velocity_record, **common)
    return SourceVelocity(frequencies=np.array([result.frequency]), velocity=rec.velocity,
                          **common)


def hologram_report_figures(result: HologramResult) -> list[tuple[str, list]]:
    """The figures of a hologram's ``report.html``, section by section.

    Parameters
    ----------
    result : HologramResult
        From :func:`holoprobe.characterize.characterize_hologram`.

    Returns
    -------
    list of (str, list of matplotlib.figure.Figure)
        Section heading and its figures, in the report's order.
    """
    from holoprobe import report as rp

    rec = result.reconstruction
    surf = rec.unrolled
    sections: list[tuple[str, list]] = [("Hologram", [rp.plot_plane_amplitude_phase(
        result.pressure, result.grid.x, result.grid.y, title="hologram (scan plane)",
        frequency=result.frequency, amplitude_unit="Pa")])]
    rho_c = result.hologram.medium.impedance
    vmap = surf.to_map(rec.velocity[:, 0] * rho_c, fill=0.0)
    sections.append(("Source surface velocity (unrolled)", [rp.plot_plane_amplitude_phase(
        vmap, surf.u, surf.v, title="ρ0c0 × normal velocity on the source (unrolled)",
        frequency=result.frequency, amplitude_unit="Pa", phase_mask_db=-20.0)]))
    f = result.focal
    if f is not None:
        sections.append(("Focal field", [rp.plot_focal_profiles(
            f.axial_coordinate, f.axial_profile, f.transverse_coordinate, f.transverse_e1,
            f.transverse_e2, axial_length=f.axial_length, widths=(f.width_e1, f.width_e2)),
            rp.plot_focal_volume(f.volume_axes, f.volume)]))
    sections.append(("Aligned geometry", [rp.plot_aligned_geometry(
        result.grid.x, result.grid.y, surf.surface.points[rec.inside], rec.geometry.axis,
        rec.geometry.apex, None if result.alignment is None else result.alignment.focus)]))
    return sections


def write_hologram_outputs(result: HologramResult, out: str | os.PathLike, *,
                           inputs: Sequence[str | os.PathLike] = (),
                           overwrite: bool = False, report: bool = True,
                           config: dict[str, Any] | None = None) -> dict[str, Path]:
    """Write summary.json, source.h5, focal_volume.h5 (focused sources) and (optionally)
    report.html into ``out``.

    Parameters
    ----------
    result : HologramResult
    out : str or PathLike
        Output directory (created).
    inputs : list of paths
        Input files (never overwritten; listed in the summary).
    overwrite : bool
        Replace existing outputs.
    report : bool
        Write report.html.
    config : dict, optional
        The configuration used (stored in the summary).

    Returns
    -------
    dict
        File name → path written.
    """
    out = Path(out)
    if not overwrite:
        for name in HOLOGRAM_OUTPUT_FILES:
            if (out / name).exists():
                raise InputError("exists (pass --overwrite to replace it)", file=str(out / name))
    out.mkdir(parents=True, exist_ok=True)
    summary = hologram_summary(result)
    summary["inputs"] = [str(p) for p in inputs]
    if config is not None:
        summary["config"] = config
    protect = tuple(inputs)
    written = {"summary.json": write_json(out / "summary.json", summary, overwrite=overwrite,
                                          protect=protect),
               "source.h5": write_source(out / "source.h5", source_velocity(result),
                                         overwrite=overwrite)}
    f = result.focal
    if f is not None:
        written["focal_volume.h5"] = write_focal_volume(
            out / "focal_volume.h5", f.volume, f.volume_axes, focus=f.focus, axis=f.axis,
            e1=f.e1, e2=f.e2, frequency=result.frequency, overwrite=overwrite,
            protect=protect)
    if report:
        from holoprobe.report import build_report

        params = {k: v for k, v in summary.items()
                  if k in ("alignment", "source", "acoustic_power", "focal_field",
                           "uncertainty")}
        written["report.html"] = build_report(
            out / "report.html", title="holoprobe: source characterization from a hologram",
            parameters=params, sections=hologram_report_figures(result),
            warnings=result.warnings,
            overwrite=overwrite, protect=protect)
    return written
