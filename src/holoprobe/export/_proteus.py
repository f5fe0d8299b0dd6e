"""Export to (and import from) PROTEUS, the MATLAB ultrasound simulator.

Files written by :func:`export_proteus` into one directory (MATLAB v5, readable by
``scipy.io.loadmat`` and MATLAB's ``load``):

``Transducer.mat``
    One variable ``Transducer``: a struct with exactly the fields of the
    ``Transducer`` struct of a PROTEUS settings file, in its order and units::

        Type                     char   'Custom linear'
        Configuration            char   'Linear'
        NumberOfElements         double N
        Pitch                    double m
        ElementWidth             double m
        ElementHeight            double m (active elevation height H)
        ElevationFocus           double m (Inf: no lens)
        BandwidthLow             double Hz (−6 dB edges of the transmit IR spectrum)
        BandwidthHigh            double Hz
        CenterFrequency          double Hz (spectral peak of the transmit IR)
        ImpulseResponseType      char   'Load file'
        SamplingRate             double Hz (250e6)
        TransmitImpulseResponse  double (1, n) Pa/(V·s)
        ReceiveImpulseResponse   double (1, m) ADCL/(Pa·s) (or V/(Pa·s); (1, 0) if none)

``IR_transmit.mat``, ``IR_receive.mat``
    Variables ``IR`` (row vector, same units as above) and ``Fs`` (Hz, 250e6), so
    that ``S = load(f); S.IR`` is the impulse response (what the PROTEUS GUI's
    "Load file" expects). ``IR_receive.mat`` only when the model has a receive IR.

Units: PROTEUS computes the surface pressure ``ρ0 c0 u = conv(V, IR_T) / Fs``: the
transmit IR is ρ0·c0·u per volt-second, exactly holoprobe's ``Pa/(V*s)``
(reference_spec 2.8), so no rescaling is needed; IRs are resampled to 250 MHz
(band-limited, :func:`holoprobe.signal.resample`) when they are at another rate.

Axes: PROTEUS has x along the propagation direction, y lateral and z elevation;
holoprobe has x lateral, y elevation, z propagation. :func:`to_proteus_axes` and
:func:`from_proteus_axes` convert point coordinates. The Transducer struct itself
holds no coordinates: the array is centred on PROTEUS's origin, facing +x, and the
model's ``aperture_center``, element sensitivities/delays, parameters and
provenance are not part of the PROTEUS description. A convex model is refused: the
struct has no field for element positions, normals or a radius of curvature.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np
import scipy.io
from numpy.typing import ArrayLike, NDArray

from holoprobe.errors import InputError
from holoprobe.geometry import Medium

__all__ = [
    "PROTEUS_IR_SAMPLING_RATE",
    "PROTEUS_TRANSDUCER_FIELDS",
    "export_proteus",
    "from_proteus_axes",
    "import_proteus",
    "proteus_transducer_struct",
    "to_proteus_axes",
]

PROTEUS_IR_SAMPLING_RATE = 250e6
"""Sampling rate of impulse responses in PROTEUS files, Hz."""

PROTEUS_TRANSDUCER_FIELDS = (
    "Type", "Configuration", "NumberOfElements", "Pitch", "ElementWidth", "ElementHeight",
    "ElevationFocus", "BandwidthLow", "BandwidthHigh", "CenterFrequency",
    "ImpulseResponseType", "SamplingRate", "TransmitImpulseResponse",
    "ReceiveImpulseResponse",
)
"""Field names (and order) of the ``Transducer`` struct of a PROTEUS settings file."""

# names under which the spectral summary travels in VirtualTransducer.parameters, so
# that PROTEUS → holoprobe → PROTEUS keeps the values of the original file
_PARAM_KEYS = {
    "BandwidthLow": "proteus.bandwidth_low",
    "BandwidthHigh": "proteus.bandwidth_high",
    "CenterFrequency": "proteus.center_frequency",
}


# --------------------------------------------------------------------------- axes
def to_proteus_axes(points: ArrayLike) -> NDArray[np.float64]:
    """Holoprobe (x lateral, y elevation, z propagation) → PROTEUS (x prop., y lat., z elev.).

    Parameters
    ----------
    points : array_like, shape (..., 3)
        Coordinates in m, holoprobe axes.

    Returns
    -------
    ndarray, shape (..., 3)
        ``(z, x, y)``: the same points in PROTEUS axes.
    """
    p = np.asarray(points, dtype=float)
    if p.shape[-1:] != (3,):
        raise InputError(f"expected coordinates (..., 3), got shape {p.shape}", field="points")
    return p[..., [2, 0, 1]]


def from_proteus_axes(points: ArrayLike) -> NDArray[np.float64]:
    """PROTEUS axes → holoprobe axes (inverse of :func:`to_proteus_axes`)."""
    p = np.asarray(points, dtype=float)
    if p.shape[-1:] != (3,):
        raise InputError(f"expected coordinates (..., 3), got shape {p.shape}", field="points")
    return p[..., [1, 2, 0]]


# --------------------------------------------------------------------------- export
def _to_250(ir: NDArray, fs: float, rate: float) -> NDArray[np.float64]:
    if math.isclose(fs, rate, rel_tol=1e-12):
        return np.asarray(ir, dtype=float)
    from holoprobe.signal import resample

    # an IR is a density in time (per second): its sample values are kept
    return np.asarray(resample(ir, fs, rate, method="fft"), dtype=float)


def proteus_transducer_struct(vt: Any, *, sampling_rate: float = PROTEUS_IR_SAMPLING_RATE,
                              transducer_type: str = "Custom linear",
                              bandwidth_level_db: float = -6.0) -> dict[str, Any]:
    """The PROTEUS ``Transducer`` struct of a virtual transducer, as an ordered dict.

    Parameters
    ----------
    vt : VirtualTransducer
        The model.
    sampling_rate : float
        Rate of the IRs in the struct (PROTEUS: 250 MHz).
    transducer_type : str
        The ``Type`` field ("Custom linear": PROTEUS uses the given geometry and IRs).
    bandwidth_level_db : float
        Level of ``BandwidthLow``/``BandwidthHigh`` re the peak of the transmit IR
        amplitude spectrum. Values found in ``vt.parameters`` under
        ``proteus.bandwidth_low``, ``proteus.bandwidth_high`` and
        ``proteus.center_frequency`` (set by :func:`import_proteus`) take precedence.

    Returns
    -------
    dict
        Field name → value, in :data:`PROTEUS_TRANSDUCER_FIELDS` order; IRs as
        (1, n) float arrays.
    """
    from holoprobe.signal import spectrum_summary
    from holoprobe.transducer import VirtualTransducer

    if not isinstance(vt, VirtualTransducer):
        raise InputError("expected a holoprobe.transducer.VirtualTransducer", field="vt")
    if vt.is_curved:
        raise InputError("PROTEUS's Transducer struct describes a flat linear array "
                         "(Configuration 'Linear', no element positions or radius); this "
                         "convex model cannot be written without losing its curvature: "
                         "use the UFF, Verasonics or k-Wave export", field="vt")
    rate = float(sampling_rate)
    if not (math.isfinite(rate) and rate > 0):
        raise InputError(f"expected a positive sampling rate in Hz, got {rate!r}",
                         field="sampling_rate")
    tx = _to_250(vt.transmit_impulse_response, vt.transmit_sampling_rate, rate)
    rx = (np.zeros(0) if vt.receive_impulse_response is None
          or vt.receive_sampling_rate is None else
          _to_250(vt.receive_impulse_response, float(vt.receive_sampling_rate), rate))
    summary = spectrum_summary(vt.transmit_impulse_response, vt.transmit_sampling_rate,
                               level_db=bandwidth_level_db)
    computed = {"BandwidthLow": summary.f_low, "BandwidthHigh": summary.f_high,
                "CenterFrequency": summary.peak_frequency}
    band = {k: float(vt.parameters.get(p, computed[k])) for k, p in _PARAM_KEYS.items()}
    return {
        "Type": str(transducer_type),
        "Configuration": "Linear",
        "NumberOfElements": float(vt.element_count),
        "Pitch": float(vt.pitch),
        "ElementWidth": float(vt.element_width),
        "ElementHeight": float(vt.element_height),
        "ElevationFocus": float(vt.lens_focus),
        "BandwidthLow": band["BandwidthLow"],
        "BandwidthHigh": band["BandwidthHigh"],
        "CenterFrequency": band["CenterFrequency"],
        "ImpulseResponseType": "Load file",
        "SamplingRate": rate,
        "TransmitImpulseResponse": tx.reshape(1, -1),
        "ReceiveImpulseResponse": rx.reshape(1, -1),
    }


def _savemat(path: Path, variables: dict[str, Any], overwrite: bool) -> None:
    from holoprobe.io import atomic_write

    with atomic_write(path, overwrite=overwrite) as tmp:
        scipy.io.savemat(tmp, variables, format="5", oned_as="row", do_compression=False)


def export_proteus(vt: Any, out_dir: str | os.PathLike, *, overwrite: bool = False,
                   sampling_rate: float = PROTEUS_IR_SAMPLING_RATE,
                   transducer_type: str = "Custom linear",
                   bandwidth_level_db: float = -6.0) -> dict[str, Path]:
    """Write a virtual transducer as PROTEUS files (format in the module docstring).

    Parameters
    ----------
    vt : VirtualTransducer
        The model.
    out_dir : str or PathLike
        Output directory (created when missing).
    overwrite : bool
        Replace existing files (default: refuse with :class:`InputError`).
    sampling_rate, transducer_type, bandwidth_level_db
        See :func:`proteus_transducer_struct`.

    Returns
    -------
    dict of str to Path
        ``{"transducer": …/Transducer.mat, "transmit": …/IR_transmit.mat}`` and
        ``"receive": …/IR_receive.mat`` when the model has a receive IR. Each file is
        written atomically.
    """
    struct = proteus_transducer_struct(vt, sampling_rate=sampling_rate,
                                       transducer_type=transducer_type,
                                       bandwidth_level_db=bandwidth_level_db)
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError("expected an output directory", file=str(out))
    files = {"transducer": out / "Transducer.mat", "transmit": out / "IR_transmit.mat"}
    if struct["ReceiveImpulseResponse"].size:
        files["receive"] = out / "IR_receive.mat"
    if not overwrite:
        for path in files.values():
            if path.exists():
                raise InputError("already exists; pass overwrite=True to replace it",
                                 file=str(path))
    _savemat(files["transducer"], {"Transducer": struct}, overwrite)
    rate = struct["SamplingRate"]
    _savemat(files["transmit"], {"IR": struct["TransmitImpulseResponse"], "Fs": rate},
             overwrite)
    if "receive" in files:
        _savemat(files["receive"], {"IR": struct["ReceiveImpulseResponse"], "Fs": rate},
                 overwrite)
    return files


# --------------------------------------------------------------------------- import
def _load(path: Path) -> dict[str, Any]:
    """Variables of a MATLAB v5 or v7.3 file, structs as dicts (:func:`holoprobe.io.load_mat`)."""
    from holoprobe.io import load_mat

    return load_mat(path)


def _field(struct: Any, name: str, file: str) -> Any:
    if isinstance(struct, dict) and name in struct:
        return struct[name]
    raise InputError("missing field of the Transducer struct", file=file,
                     field=f"Transducer.{name}")


def _number(struct: Any, name: str, file: str) -> float:
    value = np.asarray(_field(struct, name, file), dtype=float).reshape(-1)
    if value.size != 1:
        raise InputError(f"expected one number, got {value.size}", file=file,
                         field=f"Transducer.{name}")
    return float(value[0])


def _ir_file(path: Path) -> tuple[NDArray[np.float64], float]:
    data = _load(path)
    if "IR" not in data or "Fs" not in data:
        raise InputError("expected variables IR (row vector) and Fs (Hz)", file=str(path))
    ir = np.asarray(data["IR"], dtype=float).reshape(-1)
    fs = float(np.asarray(data["Fs"], dtype=float).reshape(-1)[0])
    return ir, fs


def import_proteus(path: str | os.PathLike, *, medium: Medium | None = None,
                   name: str = "") -> Any:
    """Read PROTEUS transducer files back into a :class:`VirtualTransducer`.

    Parameters
    ----------
    path : str or PathLike
        A directory written by :func:`export_proteus` (``Transducer.mat`` and the
        ``IR_transmit.mat`` / ``IR_receive.mat`` files), or one ``.mat`` file with a
        ``Transducer`` struct (a PROTEUS settings file, or ``Transducer.mat``). IR
        files next to the ``.mat`` file take precedence over the IR arrays of the
        struct.
    medium : Medium, optional
        ρ0, c0. Default: the ``Medium`` struct of a settings file
        (``SpeedOfSound``, ``Density``) when there is one, else water.
    name : str
        Label of the model (default: the struct's ``Type``).

    Returns
    -------
    VirtualTransducer
        Geometry, focus and IRs of the files; the struct's bandwidth and centre
        frequency in ``parameters`` (``proteus.*``), so that exporting again writes
        the same files.

    Raises
    ------
    InputError
        A missing file, struct or field, or no transmit impulse response.
    """
    from holoprobe.transducer import Provenance, VirtualTransducer

    p = Path(path)
    mat = p / "Transducer.mat" if p.is_dir() else p
    if not mat.is_file():
        raise InputError("no such PROTEUS transducer file", file=str(mat))
    file = str(mat)
    data = _load(mat)
    if "Transducer" not in data:
        raise InputError("expected a variable 'Transducer' (struct)", file=file,
                         field="Transducer")
    tr = data["Transducer"]
    rate = _number(tr, "SamplingRate", file)
    tx_file, rx_file = mat.parent / "IR_transmit.mat", mat.parent / "IR_receive.mat"
    if tx_file.is_file():
        tx, tx_fs = _ir_file(tx_file)
    else:
        tx = np.asarray(_field(tr, "TransmitImpulseResponse", file), dtype=float).reshape(-1)
        tx_fs = rate
    if tx.size < 2:
        raise InputError("no transmit impulse response (struct field empty and no "
                         "IR_transmit.mat)", file=file, field="Transducer.TransmitImpulseResponse")
    if rx_file.is_file():
        rx, rx_fs = _ir_file(rx_file)
    else:
        try:
            rx = np.asarray(_field(tr, "ReceiveImpulseResponse", file), dtype=float).reshape(-1)
        except InputError:
            rx = np.zeros(0)
        rx_fs = rate
    if medium is None:
        med = data.get("Medium")
        medium = Medium()
        if isinstance(med, dict) and "SpeedOfSound" in med and "Density" in med:
            medium = Medium(density=float(np.asarray(med["Density"]).reshape(-1)[0]),
                            sound_speed=float(np.asarray(med["SpeedOfSound"]).reshape(-1)[0]))
    params = {}
    for key, pkey in _PARAM_KEYS.items():
        try:
            params[pkey] = _number(tr, key, file)
        except InputError:
            continue
    try:
        type_ = str(_field(tr, "Type", file))
    except InputError:
        type_ = ""
    return VirtualTransducer(
        element_count=round(_number(tr, "NumberOfElements", file)),
        pitch=_number(tr, "Pitch", file),
        element_width=_number(tr, "ElementWidth", file),
        element_height=_number(tr, "ElementHeight", file),
        lens_focus=_number(tr, "ElevationFocus", file),
        transmit_impulse_response=tx,
        transmit_sampling_rate=tx_fs,
        receive_impulse_response=rx if rx.size >= 2 else None,
        receive_sampling_rate=rx_fs if rx.size >= 2 else None,
        medium=medium,
        parameters=params,
        provenance=Provenance.from_files([mat], notes="imported from PROTEUS files"),
        name=name or type_,
    )
