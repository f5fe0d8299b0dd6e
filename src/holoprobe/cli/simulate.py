"""``holoprobe simulate``: synthetic measurements with known truth (the digital twin).

A thin shell over :func:`holoprobe.simulate.simulate_scan`,
:func:`holoprobe.simulate.simulate_echo` and :func:`holoprobe.simulate.write_simulation`.
Lengths are given in mm, times in µs, rates in MHz and angles in degrees at this
boundary; everything is SI inside.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any

import typer

from holoprobe.cli._app import OutputDirectory, new_app
from holoprobe.errors import InputError

app = new_app("Simulate a hydrophone scan, a reflector echo or a hologram with known truth.")

_FORMATS = ("native", "reference-mat")


def _model(preset: str, elements: int | None, edge_mode: float,
           variation: _Variation | None = None):
    from holoprobe.simulate import ArrayModel, EdgeMode

    overrides: dict[str, Any] = {}
    if elements is not None:
        overrides["element_count"] = elements
    if edge_mode:
        overrides["edge_mode"] = EdgeMode(amplitude=edge_mode)
    if preset.split(":")[0] in ("matrix", "sparse", "row-column"):
        if overrides:
            raise InputError("--elements and --edge-mode apply to file presets only",
                             field="--preset")
        model = _flat_array_model(preset)
    else:
        model = ArrayModel.from_preset(preset, **overrides)
    if variation is None:
        return model
    return model.with_element_variation(
        amplitude_rms=variation.amplitude_rms, delay_rms=variation.delay_rms_ns * 1e-9,
        receive_gain_rms=variation.receive_gain_rms, dead=_indices(variation.dead),
        seed=variation.seed)


def _flat_array_model(spec: str):
    """A 2-D twin (3 MHz, pitch 0.3 mm, kerf 0.03 mm, no lens) from ``--preset``:
    ``matrix:NXxNY``, ``sparse:NofNXxNY[:spiral|random[:SEED]]`` (taper 0.5) or
    ``row-column:N[:columns|rows]`` (the set that transmits)."""
    from holoprobe.geometry import sparse_layout
    from holoprobe.simulate import ArrayModel

    kind, *parts = spec.split(":")
    try:
        if kind == "row-column" and len(parts) in (1, 2):
            return ArrayModel.row_column(int(parts[0]), transmit=[*parts, "columns"][1])
        count, _, grid = parts[0].rpartition("of")
        nx, ny = (int(v) for v in grid.lower().split("x"))
        if kind == "matrix" and len(parts) == 1 and not count:
            return ArrayModel.matrix(nx, ny)
        if kind == "sparse" and count and 1 <= len(parts) <= 3:
            layout = parts[1] if len(parts) > 1 else "spiral"
            seed = int(parts[2]) if len(parts) > 2 else 0
            return ArrayModel.matrix(nx, ny, active=sparse_layout(nx, ny, int(count),
                                                                  layout=layout, seed=seed))
    except (ValueError, IndexError):
        pass
    raise InputError(f"expected matrix:NXxNY, sparse:NofNXxNY[:spiral|random[:SEED]] or "
                     f"row-column:N[:columns|rows], got {spec!r}", field="--preset")


def _indices(text: str) -> list[int]:
    try:
        return [int(v) for v in text.replace(",", " ").split()]
    except ValueError:
        raise InputError(f"expected 0-based element indices separated by commas, got "
                         f"{text!r}", field="--dead") from None


def _media(sound_speed: float | None, file_sound_speed: float | None):
    """(true medium, medium written into the file)."""
    from holoprobe.geometry import Medium

    true = Medium() if sound_speed is None else Medium(sound_speed=sound_speed)
    recorded = None if file_sound_speed is None else Medium(true.density, file_sound_speed)
    return true, recorded


class _Variation:
    """Element-to-element variation options shared by ``scan`` and ``receive``."""

    def __init__(self, amplitude_rms: float, delay_rms_ns: float, receive_gain_rms: float,
                 dead: str, seed: int) -> None:
        self.amplitude_rms, self.delay_rms_ns = amplitude_rms, delay_rms_ns
        self.receive_gain_rms, self.dead, self.seed = receive_gain_rms, dead, seed


_AmpRms = Annotated[float, typer.Option(
    help="Relative rms element-to-element transmit amplitude variation (0.05: ±5 %).")]
_DelayRms = Annotated[float, typer.Option(help="Rms element delay variation in ns.")]
_GainRms = Annotated[float, typer.Option(
    help="Relative rms element-to-element receive gain variation.")]
_Dead = Annotated[str, typer.Option(
    help="Dead elements: 0-based indices separated by commas (e.g. '40,95').")]
_ElementSeed = Annotated[int, typer.Option(help="Seed of the element variation.")]
_SoundSpeed = Annotated[float | None, typer.Option(
    help="True water sound speed in m/s (default 1481).")]
_FileSoundSpeed = Annotated[float | None, typer.Option(
    help="Sound speed written into the measurement file in m/s (default: the true one).")]
# options shared by `simulate scan` and `simulate echo`
_PointsPerWavelength = Annotated[float, typer.Option(
    help="Quadrature points per shortest wavelength.")]
_BandThreshold = Annotated[float, typer.Option(
    help="Level that delimits the simulated band, dB.")]
_Format = Annotated[str, typer.Option("--format", help="native or reference-mat.")]
_Overwrite = Annotated[bool, typer.Option(help="Replace existing files.")]
_Quiet = Annotated[bool, typer.Option(help="No progress bar, no file list.")]


def _check_format(fmt: str) -> str:
    if fmt not in _FORMATS:
        raise InputError(f"expected one of {_FORMATS}, got {fmt!r}", field="--format")
    return fmt


def _finish(out: Path, measurement, truth, fmt: str, overwrite: bool, quiet: bool) -> None:
    from holoprobe.simulate import write_simulation

    files = write_simulation(out, measurement, truth,
                             format="native" if fmt == "native" else "reference-mat",
                             overwrite=overwrite)
    if not quiet:
        for path in files:
            typer.echo(str(path))


@app.command()
def scan(
    out: OutputDirectory,
    preset: Annotated[str, typer.Option(
        help="Probe preset (data file), or a 2-D twin: matrix:32x32, "
             "sparse:256of32x32[:spiral|random[:SEED]], row-column:32[:columns|rows].")
    ] = "p4-1",
    pose_deg: Annotated[tuple[float, float, float], typer.Option(
        "--pose-deg", help="Scan-plane angles θx θy θz in degrees.")] = (-0.0793, 0.6505,
                                                                         -0.7735),
    origin_mm: Annotated[tuple[float, float, float], typer.Option(
        "--origin-mm", help="Scan-plane origin x0 y0 z0 in mm.")] = (-0.306, -0.064, 3.569),
    size_mm: Annotated[tuple[float, float], typer.Option(
        "--size-mm", help="Scan size along u (x) and v (y) in mm.")] = (36.0, 24.0),
    step_mm: Annotated[tuple[float, float], typer.Option(
        "--step-mm", help="Scan step along u and v in mm.")] = (0.15, 0.15),
    sampling_rate_mhz: Annotated[float, typer.Option(help="Sampling rate in MHz.")] = 25.0,
    n_samples: Annotated[int, typer.Option(help="Samples per record.")] = 1024,
    start_time_us: Annotated[float, typer.Option(help="Time of sample 0 in µs.")] = 0.0,
    snr_db: Annotated[float, typer.Option(help="Peak SNR in dB (inf: no noise).")] = 40.0,
    seed: Annotated[int, typer.Option(help="Noise seed.")] = 0,
    quantization_bits: Annotated[int | None, typer.Option(help="ADC bits (none).")] = None,
    pressure: Annotated[bool, typer.Option(
        help="Record pressure in Pa instead of hydrophone voltage.")] = False,
    elements: Annotated[int | None, typer.Option(help="Override the element count.")] = None,
    edge_mode: Annotated[float, typer.Option(
        help="Relative amplitude of the antisymmetric edge mode (0: off).")] = 0.0,
    element_amplitude_rms: _AmpRms = 0.0,
    element_delay_rms_ns: _DelayRms = 0.0,
    receive_gain_rms: _GainRms = 0.0,
    dead: _Dead = "",
    element_seed: _ElementSeed = 0,
    jitter_um: Annotated[float, typer.Option(
        help="Rms scan-position error in µm along each axis of the scan plane.")] = 0.0,
    sound_speed: _SoundSpeed = None,
    file_sound_speed: _FileSoundSpeed = None,
    points_per_wavelength: _PointsPerWavelength = 4.0,
    band_threshold_db: _BandThreshold = -30.0,
    fmt: _Format = "native",
    overwrite: _Overwrite = False,
    quiet: _Quiet = False,
) -> None:
    """Simulate a hydrophone raster scan in front of the probe (writes truth.json too)."""
    from holoprobe.geometry import Pose
    from holoprobe.simulate import simulate_scan

    _check_format(fmt)
    pose = Pose.from_degrees(*pose_deg, origin=[v * 1e-3 for v in origin_mm])
    variation = _Variation(element_amplitude_rms, element_delay_rms_ns, receive_gain_rms,
                           dead, element_seed)
    medium, recorded = _media(sound_speed, file_sound_speed)
    measurement, truth = simulate_scan(
        _model(preset, elements, edge_mode, variation), pose=pose, medium=medium,
        recorded_medium=recorded, position_jitter=jitter_um * 1e-6,
        size=[v * 1e-3 for v in size_mm],
        step=[v * 1e-3 for v in step_mm], sampling_rate=sampling_rate_mhz * 1e6,
        n_samples=n_samples, start_time=start_time_us * 1e-6,
        calibration=None if pressure else "default",
        snr_db=None if math.isinf(snr_db) else snr_db, seed=seed,
        quantization_bits=quantization_bits, points_per_wavelength=points_per_wavelength,
        band_threshold_db=band_threshold_db, progress=None if not quiet else False)
    _finish(out, measurement, truth, fmt, overwrite, quiet)


@app.command()
def receive(
    out: OutputDirectory,
    preset: Annotated[str, typer.Option(help="Probe preset (data file).")] = "p4-1",
    distance_mm: Annotated[float, typer.Option(
        help="Plate distance d in mm.")] = 44.8978,
    tilt_deg: Annotated[float, typer.Option(
        help="Virtual-sensor tilt θy' in degrees (the plate is tilted by half).")
    ] = 3.1672532951380172,
    rp: Annotated[float, typer.Option(help="Plate reflection coefficient Rp.")] = 0.78,
    back_wall: Annotated[bool, typer.Option(help="Add the back-wall echo.")] = True,
    plate_thickness_mm: Annotated[float, typer.Option(help="Plate thickness in mm.")] = 12.7,
    plate_sound_speed: Annotated[float, typer.Option(
        help="Plate sound speed in m/s.")] = 5900.0,
    sampling_rate_mhz: Annotated[float, typer.Option(help="Sampling rate in MHz.")] = 62.5,
    n_samples: Annotated[int | None, typer.Option(
        help="Samples per channel (default: 10 µs past the back wall).")] = None,
    snr_db: Annotated[float, typer.Option(help="Peak SNR in dB (inf: no noise).")] = 40.0,
    seed: Annotated[int, typer.Option(help="Noise seed.")] = 0,
    quantization_bits: Annotated[int | None, typer.Option(help="ADC bits (none).")] = None,
    elements: Annotated[int | None, typer.Option(help="Override the element count.")] = None,
    element_amplitude_rms: _AmpRms = 0.0,
    element_delay_rms_ns: _DelayRms = 0.0,
    receive_gain_rms: _GainRms = 0.0,
    dead: _Dead = "",
    element_seed: _ElementSeed = 0,
    sound_speed: _SoundSpeed = None,
    file_sound_speed: _FileSoundSpeed = None,
    points_per_wavelength: _PointsPerWavelength = 4.0,
    band_threshold_db: _BandThreshold = -30.0,
    fmt: _Format = "native",
    overwrite: _Overwrite = False,
    quiet: _Quiet = False,
) -> None:
    """Simulate the element RF of the flat-reflector (receive) experiment + truth.json."""
    from holoprobe.simulate import simulate_echo

    _check_format(fmt)
    quantization = quantization_bits
    full_scale = None if quantization is None else 2.0 ** (quantization - 1)
    variation = _Variation(element_amplitude_rms, element_delay_rms_ns, receive_gain_rms,
                           dead, element_seed)
    medium, recorded = _media(sound_speed, file_sound_speed)
    measurement, truth = simulate_echo(
        _model(preset, elements, 0.0, variation), medium=medium, recorded_medium=recorded,
        plate_distance=distance_mm * 1e-3,
        virtual_tilt=math.radians(tilt_deg), reflection_coefficient=rp, back_wall=back_wall,
        plate_thickness=plate_thickness_mm * 1e-3, plate_sound_speed=plate_sound_speed,
        sampling_rate=sampling_rate_mhz * 1e6, n_samples=n_samples,
        snr_db=None if math.isinf(snr_db) else snr_db, seed=seed,
        quantization_bits=quantization, full_scale=full_scale,
        points_per_wavelength=points_per_wavelength, band_threshold_db=band_threshold_db,
        progress=None if not quiet else False)
    _finish(out, measurement, truth, fmt, overwrite, quiet)


_SOURCES = ("spherical-cap", "flat-disc", "flat-rectangle")


def _gains(text: str) -> tuple[float, ...]:
    try:
        return tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise InputError(f"expected comma-separated numbers, got {text!r}",
                         field="--sector-gains") from None


@app.command()
def hologram(
    out: OutputDirectory,
    source: Annotated[str, typer.Option(
        help="spherical-cap, flat-disc or flat-rectangle.")] = "spherical-cap",
    aperture_mm: Annotated[float, typer.Option(
        help="Aperture diameter in mm (a rectangle's width, along x).")] = 40.0,
    height_mm: Annotated[float | None, typer.Option(
        help="flat-rectangle: height in mm along y, ≤ the width (default: the width).")] = None,
    radius_of_curvature_mm: Annotated[float, typer.Option(
        help="Radius of curvature in mm (spherical cap).")] = 40.0,
    opening_mm: Annotated[float, typer.Option(help="Central opening diameter in mm.")] = 0.0,
    frequency_mhz: Annotated[float, typer.Option(help="(Centre) frequency in MHz.")] = 1.0,
    signal: Annotated[str, typer.Option(help="cw or transient (tone burst).")] = "cw",
    cycles: Annotated[float, typer.Option(help="Tone-burst cycles (transient).")] = 5.0,
    z_mm: Annotated[float | None, typer.Option(
        help="Apex distance behind the scan plane in mm (default R/2 or 10 λ).")] = None,
    tilt_deg: Annotated[tuple[float, float], typer.Option(
        help="Source tilt θx θy in degrees.")] = (0.0, 0.0),
    offset_mm: Annotated[tuple[float, float], typer.Option(
        help="Lateral apex position x y in mm (scan coordinates).")] = (0.0, 0.0),
    points: Annotated[tuple[int, int], typer.Option(help="Scan points nx ny.")] = (61, 61),
    step_mm: Annotated[tuple[float, float] | None, typer.Option(
        help="Scan step dx dy in mm (default λ/2).")] = None,
    velocity: Annotated[float, typer.Option(help="Normal velocity amplitude, m/s.")] = 0.1,
    dead_sector_deg: Annotated[tuple[float, float] | None, typer.Option(
        help="A dead sector φ_start φ_end in degrees.")] = None,
    phase_patch: Annotated[tuple[float, float, float, float] | None, typer.Option(
        help="A phase defect: x y radius (mm) and phase (deg).")] = None,
    sector_gains: Annotated[str, typer.Option(
        help="Segments driven together: comma-separated gains of equal sectors from +x "
             "(e.g. 1,1,0.5,1,1,1).")] = "",
    snr_db: Annotated[float, typer.Option(help="Peak SNR in dB (inf: no noise).")] = 40.0,
    seed: Annotated[int, typer.Option(help="Noise seed.")] = 0,
    fmt: Annotated[str, typer.Option("--format", help="native or mat.")] = "native",
    mat_version: Annotated[str, typer.Option(help="MAT-file version 5 or 7.3.")] = "5",
    grid_layout: Annotated[str, typer.Option(
        help="mat: meshgrid, vectors, nodes, flattened ([n, nt] on axis vectors, x "
             "fastest) or flattened-y (y fastest)."
    )] = "meshgrid",
    descending: Annotated[str, typer.Option(
        help="mat: store these grid axes in decreasing order (x, y or xy).")] = "",
    power: Annotated[bool, typer.Option(
        help="Compute the true acoustic power (a few seconds).")] = True,
    focus: Annotated[bool, typer.Option(
        help="Compute the true focal maximum and lobe axis (a few seconds).")] = True,
    overwrite: Annotated[bool, typer.Option(help="Replace existing files.")] = False,
    quiet: Annotated[bool, typer.Option(help="No file list.")] = False,
) -> None:
    """Simulate a CW or transient hologram of a bowl, a disc or a rectangle (writes
    truth.json too)."""
    from holoprobe.geometry import SourceGeometry
    from holoprobe.simulate import VelocityMap, simulate_hologram, write_simulation

    if source not in _SOURCES:
        raise InputError(f"expected one of {_SOURCES}, got {source!r}", field="--source")
    if fmt not in ("native", "mat"):
        raise InputError(f"expected 'native' or 'mat', got {fmt!r}", field="--format")
    roc = radius_of_curvature_mm * 1e-3 if source == "spherical-cap" else None
    if descending not in ("", "x", "y", "xy"):
        raise InputError(f"expected x, y or xy, got {descending!r}", field="--descending")
    if height_mm is not None and source != "flat-rectangle":
        raise InputError(f"a height is for --source flat-rectangle, got --source {source}",
                         field="--height-mm")
    if opening_mm and source == "flat-rectangle":
        raise InputError("a rectangle has no central opening", field="--opening-mm")
    height = aperture_mm if height_mm is None else height_mm
    if height > aperture_mm:
        raise InputError(f"expected at most the width ({aperture_mm:g} mm; the longer side "
                         f"lies along x), got {height:g}", field="--height-mm")
    geometry = SourceGeometry(source, min(aperture_mm, height) * 1e-3,
                              max(aperture_mm, height) * 1e-3, roc, opening_mm * 1e-3)
    vmap = VelocityMap(
        amplitude=velocity,
        dead_sectors=() if dead_sector_deg is None else (
            (math.radians(dead_sector_deg[0]), math.radians(dead_sector_deg[1])),),
        phase_patches=() if phase_patch is None else (
            (phase_patch[0] * 1e-3, phase_patch[1] * 1e-3, phase_patch[2] * 1e-3,
             math.radians(phase_patch[3])),),
        sector_gains=_gains(sector_gains))
    holo, truth = simulate_hologram(
        geometry, frequency=frequency_mhz * 1e6, signal=signal, cycles=cycles,
        z_position=None if z_mm is None else z_mm * 1e-3,
        tilt=(math.radians(tilt_deg[0]), math.radians(tilt_deg[1])), offset=(offset_mm[0] * 1e-3,
                                                         offset_mm[1] * 1e-3),
        shape=points, step=None if step_mm is None else (step_mm[0] * 1e-3, step_mm[1] * 1e-3),
        velocity=vmap, snr_db=None if math.isinf(snr_db) else snr_db, seed=seed, power=power,
        focus=focus)
    files = write_simulation(out, holo, truth,
                             format="native" if fmt == "native" else "reference-mat",
                             mat_version=mat_version, overwrite=overwrite,
                             mat_options={"grid_layout": grid_layout,
                                          "descending": ("x" in descending,
                                                         "y" in descending)})
    if not quiet:
        for path in files:
            typer.echo(str(path))
