"""The truth of a simulation: every true parameter (JSON) and its arrays (HDF5)."""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from numpy.typing import NDArray

from holoprobe.errors import InputError
from holoprobe.geometry import Medium, Pose
from holoprobe.io import atomic_write, write_json

__all__ = ["SimulationTruth", "array_parameters", "medium_parameters", "model_parameters",
           "pose_parameters", "read_truth"]

TRUTH_JSON = "truth.json"
TRUTH_H5 = "truth.h5"
TRUTH_VERSION = 1


def pose_parameters(pose: Pose) -> dict[str, Any]:
    """A pose as JSON-ready numbers: angles in degrees (``_deg``), origin in m."""
    tx, ty, tz = pose.angles_deg
    return {"theta_x_deg": tx, "theta_y_deg": ty, "theta_z_deg": tz,
            "x0_m": pose.origin[0], "y0_m": pose.origin[1], "z0_m": pose.origin[2]}


def medium_parameters(medium: Medium, recorded: Medium | None = None) -> dict[str, Any]:
    """The true water and, when it differs, what the measurement file says (SI)."""
    recorded = medium if recorded is None else recorded
    return {"density_kg_m3": medium.density, "sound_speed_m_s": medium.sound_speed,
            "recorded_density_kg_m3": recorded.density,
            "recorded_sound_speed_m_s": recorded.sound_speed}


def model_parameters(model: Any, medium: Medium) -> dict[str, Any]:
    """Every true parameter of an :class:`~holoprobe.simulate.ArrayModel` (SI, degrees)."""
    u = model.surface_velocity(medium)
    fs = model.ir_sampling_rate
    em = model.edge_mode
    array = getattr(model, "array", None)
    return {
        "array": None if array is None else array_parameters(array),
        "name": model.name,
        "element_count": model.element_count,
        "pitch_m": model.pitch,
        "element_width_m": model.element_width,
        "kerf_m": model.pitch - model.element_width,
        "element_height_m": model.element_height,
        "aperture_width_m": model.aperture_width,
        "aperture_height_m": model.aperture_height,
        "aperture_center_m": [0.0, 0.0, 0.0],
        "geometry": (array.kind if array is not None else
                     "convex" if model.radius_of_curvature is not None else "linear"),
        "radius_of_curvature_m": model.radius_of_curvature,
        "arc_angle_deg": (None if model.radius_of_curvature is None else
                          math.degrees(model.aperture_width / model.radius_of_curvature)),
        "element_angles_deg": (None if model.radius_of_curvature is None else
                               [math.degrees(float(x) / model.radius_of_curvature)
                                for x in model.element_centers()]),
        "lens_focus_m": model.lens_focus if math.isfinite(model.lens_focus) else None,
        "lens_model": "exact: tau(y) = (sqrt((H/2)^2+F^2) - sqrt(y^2+F^2))/c0",
        "lens_delay_center_s": float(model.lens_delays(0.0, medium)),
        "baffle": "rigid",
        "center_frequency_hz": model.center_frequency,
        "apodization": [float(v) for v in model.apodization],
        "element_delays_s": [float(v) for v in model.delays],
        "receive_gains": [float(v) for v in model.receive_gains],
        "dead_elements": model.dead_elements,
        "ir_sampling_rate_hz": fs,
        "drive_area_v_s": model.drive.area,
        "drive_peak_v": model.drive.peak,
        "time_origin": ("t = 0 is the start of the drive voltage; transmit_ir, receive_ir "
                        "and drive sample 0 are at t = 0; the surface velocity at the "
                        "element ends (zero lens delay) is u(t) = (h_T * E_T)(t)/(rho0 c0)"),
        "surface_velocity_peak_time_s": float(np.argmax(np.abs(u)) / fs),
        "surface_velocity_peak_m_s": float(np.max(np.abs(u))),
        "transmit_ir_unit": "Pa/(V*s) of rho0*c0*u",
        "receive_ir_unit": "ADCL/(Pa*s)",
        "edge_mode": None if em is None or em.amplitude == 0 else {
            "amplitude_relative": em.amplitude, "frequency_hz": em.frequency,
            "cycles": em.cycles, "phase_speed_m_s": em.phase_speed, "delay_s": em.delay,
            "decay_length_m": em.decay_length if math.isfinite(em.decay_length) else None,
            "direction": em.direction, "outside_extent_m": em.outside_extent},
    }


def array_parameters(array: Any) -> dict[str, Any]:
    """An :class:`~holoprobe.geometry.ArrayGeometry` as JSON-ready numbers (m): kind,
    grid shape ``[n_x, n_y]`` (element index ``iy·n_x + ix``), pitch ``[p_x, p_y]``,
    per-element centres, normals, widths and heights in element order."""
    return {
        "kind": array.kind,
        "grid_shape": None if array.grid_shape is None else list(array.grid_shape),
        "pitch_m": None if array.pitch is None else list(array.pitch),
        "radius_of_curvature_m": array.radius_of_curvature,
        "element_positions_m": np.asarray(array.positions).tolist(),
        "element_normals": np.asarray(array.normals).tolist(),
        "element_widths_m": np.asarray(array.widths).tolist(),
        "element_heights_m": np.asarray(array.heights).tolist(),
        "grid_position": None if array.grid_position is None
        else np.asarray(array.grid_position).tolist(),
    }


@dataclass(frozen=True)
class SimulationTruth:
    """What a simulation knows and a characterization must recover.

    Attributes
    ----------
    parameters : dict
        JSON-ready true parameters in SI units, angles in degrees with ``_deg``.
    arrays : dict of str → ndarray
        Impulse responses, drive, clean signals (saved to ``truth.h5``).
    """

    parameters: dict[str, Any]
    arrays: dict[str, NDArray] = field(default_factory=dict)

    def write(self, directory: str | os.PathLike, *, overwrite: bool = False
              ) -> tuple[Path, Path]:
        """Write ``truth.json`` and ``truth.h5`` into ``directory`` (atomically)."""
        directory = Path(directory)
        directory.mkdir(parents=True, exist_ok=True)
        params = dict(self.parameters)
        params["truth_version"] = TRUTH_VERSION
        params["arrays_file"] = TRUTH_H5
        jpath, hpath = directory / TRUTH_JSON, directory / TRUTH_H5
        write_json(jpath, params, overwrite=overwrite)
        with atomic_write(hpath, overwrite=overwrite) as tmp, h5py.File(tmp, "w") as f:
            f.attrs["truth_version"] = TRUTH_VERSION
            for name, arr in self.arrays.items():
                f.create_dataset(name, data=np.asarray(arr))
        return jpath, hpath


def read_truth(directory: str | os.PathLike) -> SimulationTruth:
    """Read ``truth.json`` (and ``truth.h5`` when present) from a simulation directory."""
    directory = Path(directory)
    jpath = directory / TRUTH_JSON
    try:
        params = json.loads(jpath.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise InputError(f"cannot read the truth ({exc})", file=str(jpath)) from None
    arrays: dict[str, NDArray] = {}
    hpath = directory / TRUTH_H5
    if hpath.exists():
        with h5py.File(hpath, "r") as f:
            arrays = {name: f[name][()] for name in f}
    return SimulationTruth(params, arrays)
