"""One hologram characterization run (single-element sources), from a file or a Hologram."""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from holoprobe.characterize import (
    CharacterizationConfig,
    HologramResult,
    characterize_hologram,
    hologram_summary,
)
from holoprobe.errors import InputError
from holoprobe.io import SourceVelocity, read_hologram_any
from holoprobe.measurement import Hologram
from holoprobe.workflow._hologram_outputs import (
    hologram_report_figures,
    source_velocity,
    write_hologram_outputs,
)
from holoprobe.workflow._paths import PathLike

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["HologramRun", "characterize_hologram_file"]


@dataclass(frozen=True)
class HologramRun:
    """What one hologram characterization produced, before anything is written.

    Attributes
    ----------
    result : HologramResult
        Alignment, reconstruction, powers, uniformity, focal field (scan coordinates).
    config : CharacterizationConfig
        The configuration used (its ``hologram`` section).
    inputs : tuple of Path
        Input files (never overwritten by :meth:`save`).
    """

    result: HologramResult
    config: CharacterizationConfig
    inputs: tuple[Path, ...] = ()

    @property
    def summary(self) -> dict[str, Any]:
        """The ``summary.json`` tree (docs/formats.md)."""
        return hologram_summary(self.result)

    @property
    def source(self) -> SourceVelocity:
        """The reconstructed source (what ``source.h5`` holds)."""
        return source_velocity(self.result)

    def figures(self) -> list[tuple[str, list[Figure]]]:
        """The figures of ``report.html`` (section heading, figures)."""
        return hologram_report_figures(self.result)

    def _repr_html_(self) -> str:
        """The summary as a table of value ± standard uncertainty, with the warnings."""
        name = Path(self.inputs[0]).name if self.inputs else "hologram"
        from holoprobe.report import summary_html  # lazily: the report imports matplotlib

        return summary_html(self.summary, title=f"holoprobe hologram characterization: {name}")

    def save(self, out_dir: PathLike, *, overwrite: bool = False,
             report: bool = True) -> dict[str, Path]:
        """Write summary.json, source.h5 and report.html into ``out_dir`` (atomically)."""
        return write_hologram_outputs(self.result, out_dir, inputs=list(self.inputs),
                                      overwrite=overwrite, report=report,
                                      config=self.config.to_dict()["hologram"])


def characterize_hologram_file(
    hologram: Hologram | PathLike,
    *,
    config: CharacterizationConfig | PathLike | None = None,
    overrides: Sequence[str] = (),
    source: str | None = None,
    radius_of_curvature: float | None = None,
    aperture: float | tuple[float, float] | None = None,
    progress: bool = False,
) -> HologramRun:
    """Characterize a single-element source from a hologram (object or file).

    Parameters
    ----------
    hologram : Hologram or path
        CW or transient hologram; files in the MATLAB ``HologramSf``/``HologramTr`` layout
        or the native HDF5 one (:func:`holoprobe.io.read_hologram_any`).
    config : CharacterizationConfig or path, optional
        Configuration or TOML file; its ``[hologram]`` section is used.
    overrides : sequence of str
        ``section.key=value`` settings (the CLI's ``--set``).
    source, radius_of_curvature, aperture
        Override the file's ``Geometry`` (see :func:`holoprobe.characterize.characterize_hologram`).
    progress : bool
        Progress bars.

    Returns
    -------
    HologramRun
        ``.summary``, ``.source``, ``.save(dir)``.

    Examples
    --------
    >>> from holoprobe.workflow import characterize_hologram_file   # doctest: +SKIP
    >>> run = characterize_hologram_file("bowl.mat")                # doctest: +SKIP
    >>> run.summary["alignment"]["focus_position"], run.save("out/") # doctest: +SKIP
    """
    paths = [Path(p) for p in (hologram, config) if isinstance(p, str | os.PathLike)]
    cfg = CharacterizationConfig.resolve(config, overrides)
    if isinstance(hologram, str | os.PathLike):
        hologram = read_hologram_any(hologram, flattened_order=cfg.hologram.flattened_order)
    if not isinstance(hologram, Hologram):
        raise InputError("expected a holoprobe.measurement.Hologram or a file",
                         field="hologram")
    t0 = time.perf_counter()
    result = characterize_hologram(hologram, cfg.hologram, source=source,
                                   radius_of_curvature=radius_of_curvature, aperture=aperture,
                                   progress=progress)
    result.timings["run"] = time.perf_counter() - t0
    return HologramRun(result, cfg, tuple(paths))
