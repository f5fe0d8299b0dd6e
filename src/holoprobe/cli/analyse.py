"""``holoprobe analyse``: the paper's analyses of a characterized probe, as commands.

* ``modes DIR``: spurious antisymmetric modes in the reconstructed surface velocity
  (paper section III D, Fig. 9);
* ``phase DIR``: transmit/receive transfer functions and phase compensation (section IV B,
  Fig. 10);
* ``baffle VT.h5``: monopole vs dipole source representation by Rayleigh, angular spectrum
  and (optionally) k-wave-python (sections II C, IV C, Fig. 2).

``DIR`` is the output directory of ``holoprobe characterize``. Each analysis of a ``DIR``
adds its entry to ``DIR/summary.json`` (atomically; other entries are kept) and writes its
own page ``DIR/report_<analysis>.html`` (the main ``report.html`` is left as the
characterization wrote it). Values are SI at this boundary too, except where a flag says
otherwise (``--distance`` in m).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Annotated, Any

import typer

from holoprobe.errors import InputError

app = typer.Typer(
    help="The paper's analyses: spurious modes, phase compensation, source representation.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


def _summary(directory: Path) -> dict[str, Any]:
    path = directory / "summary.json"
    if not path.exists():
        return {}
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise InputError(f"cannot read it as JSON ({exc})", file=str(path)) from None
    return data if isinstance(data, dict) else {}


def _check_dir(directory: Path) -> Path:
    if not directory.is_dir():
        raise InputError("expected the output directory of 'holoprobe characterize'",
                         file=str(directory))
    return directory


def read_source_velocity(path: str | Path) -> dict[str, Any]:
    """Read ``source_velocity.h5`` (written by ``holoprobe characterize``).

    Returns
    -------
    dict
        ``velocity`` (nx, ny, nt) in m/s, ``x``, ``y`` in m, ``sampling_rate`` in Hz and
        ``start_time`` in s (0 when the file has none: sample n at n/fs).
    """
    import h5py
    import numpy as np

    path = Path(path)
    if not path.is_file():
        raise InputError("no such file (run 'holoprobe characterize' first)", file=str(path))
    try:
        with h5py.File(path, "r") as f:
            out: dict[str, Any] = {}
            for name in ("velocity", "x", "y", "sampling_rate"):
                if name not in f:
                    raise InputError("missing dataset", file=str(path), field=name)
                out[name] = np.asarray(f[name][()])
            out["start_time"] = float(f["start_time"][()]) if "start_time" in f else 0.0
    except OSError as exc:
        raise InputError(f"not a readable HDF5 file ({exc})", file=str(path)) from None
    out["sampling_rate"] = float(out["sampling_rate"])
    if out["velocity"].ndim != 3:
        raise InputError(f"expected shape (nx, ny, nt), got {out['velocity'].shape}",
                         file=str(path), field="velocity")
    return out


def _write_report(path: Path, title: str, rows: list, sections: list, warnings: list[str],
                  metadata: dict[str, Any]) -> Path:
    from holoprobe.report import build_report

    return build_report(path, title=title, parameters=rows, sections=sections,
                        warnings=warnings, metadata=metadata, overwrite=True)


@app.command()
def modes(
    directory: Annotated[Path, typer.Argument(help="Output directory of 'characterize'.")],
    threshold_db: Annotated[float, typer.Option(
        help="Strength (dB re the main pulse) above which the mode is reported present."
    )] = -30.0,
    edge_distance: Annotated[float | None, typer.Option(
        help="Distance (m) of the edge trace inside the aperture edge (default H/10).")
    ] = None,
    quiet: Annotated[bool, typer.Option(help="Print nothing.")] = False,
) -> None:
    """Spurious antisymmetric modes in the surface velocity (paper section III D, Fig. 9).

    Reads DIR/source_velocity.h5 and the aperture from DIR/summary.json; adds a 'modes'
    entry to DIR/summary.json and writes DIR/report_modes.html.
    """
    from holoprobe.analysis import analyse_modes, modes_figures, update_summary

    directory = _check_dir(directory)
    data = read_source_velocity(directory / "source_velocity.h5")
    summary = _summary(directory)
    ap = summary.get("aperture") if isinstance(summary.get("aperture"), dict) else None
    aperture = None
    if ap and all(isinstance(ap.get(k), int | float) for k in
                  ("center_x", "center_y", "width", "height")):
        aperture = (ap["center_x"], ap["center_y"], ap["width"], ap["height"])
    result = analyse_modes(data["velocity"], (data["x"], data["y"]), data["sampling_rate"],
                           aperture=aperture, start_time=data["start_time"],
                           threshold_db=threshold_db, edge_distance=edge_distance)
    entry = result.summary()
    entry["report"] = "report_modes.html"
    entry["aperture_source"] = "summary.json" if aperture is not None else "estimated"
    update_summary(directory, "modes", entry)
    rows = [
        ("mode present", "yes" if result.present else "no", None, ""),
        ("tail frequency", result.frequency, None, "Hz"),
        ("tail strength re main pulse", round(result.strength_db, 2), None, "dB"),
        ("odd part before the pulse (noise)",
         None if result.noise_db is None else round(result.noise_db, 2), None, "dB"),
        ("tail −6 dB fractional bandwidth", result.fractional_bandwidth, None, ""),
        ("phase velocity at the tail frequency", result.phase_velocity, None, "m/s"),
        ("main pulse peak frequency", result.main_frequency, None, "Hz"),
        ("detection threshold", threshold_db, None, "dB"),
    ]
    _write_report(directory / "report_modes.html", "Spurious modes of oscillation", rows,
                  [("Spurious modes (paper Fig. 9)", modes_figures(result))],
                  result.warnings, {"source": str(directory / "source_velocity.h5"),
                                    "criteria": result.criteria})
    if not quiet:
        verdict = "present" if result.present else "absent"
        freq = (f"{result.frequency / 1e6:.3f} MHz" if math.isfinite(result.frequency)
                else "n/a")
        typer.echo(f"spurious mode {verdict}: tail {freq}, {result.strength_db:.1f} dB re "
                   f"main pulse; report {directory / 'report_modes.html'}")


@app.command()
def phase(
    directory: Annotated[Path, typer.Argument(help="Output directory of 'characterize'.")],
    filter_group_delay: Annotated[Path | None, typer.Option(
        help="Filter datasheet with a 'Group Delay' column (default: the packaged BLP-15+).")
    ] = None,
    hydrophone_sensitivity: Annotated[Path | None, typer.Option(
        help="Hydrophone amplitude calibration (default: the packaged one).")] = None,
    no_filter: Annotated[bool, typer.Option(help="Do not compensate a filter.")] = False,
    no_hydrophone: Annotated[bool, typer.Option(
        help="Do not compensate the hydrophone's minimum phase.")] = False,
    duration: Annotated[float, typer.Option(help="Length (s) of the IRs compared.")] = 2e-6,
    quiet: Annotated[bool, typer.Option(help="Print nothing.")] = False,
) -> None:
    """Transmit/receive transfer functions and phase compensation (paper IV B, Fig. 10).

    Reads DIR/virtual_transducer.h5 (it needs a receive impulse response); adds a 'phase'
    entry to DIR/summary.json and writes DIR/report_phase.html.
    """
    from holoprobe.analysis import (
        analyse_phase,
        default_filter_phase,
        phase_figures,
        update_summary,
    )
    from holoprobe.signal import (
        default_calibration,
        filter_phase_from_group_delay,
        load_calibration,
    )
    from holoprobe.transducer import VirtualTransducer

    directory = _check_dir(directory)
    vt_path = directory / "virtual_transducer.h5"
    if not vt_path.is_file():
        raise InputError("no such file (run 'holoprobe characterize' first)", file=str(vt_path))
    vt = VirtualTransducer.load(vt_path)
    if vt.receive_impulse_response is None:
        raise InputError("the model has no receive impulse response: characterize with an "
                         "echo recording first", file=str(vt_path),
                         field="receive_impulse_response")
    filt = None if no_filter else (default_filter_phase() if filter_group_delay is None
                                   else filter_phase_from_group_delay(filter_group_delay))
    hyd = None if no_hydrophone else (default_calibration() if hydrophone_sensitivity is None
                                      else load_calibration(hydrophone_sensitivity))
    result = analyse_phase(vt.transmit_impulse_response, vt.transmit_sampling_rate,
                           vt.receive_impulse_response, vt.receive_sampling_rate,
                           filter_phase=filt, hydrophone=hyd, duration=duration)
    entry = result.summary()
    entry["report"] = "report_phase.html"
    entry["filter"] = None if filt is None else (str(filter_group_delay)
                                                 if filter_group_delay else "BLP-15+ (packaged)")
    entry["hydrophone"] = None if hyd is None else (str(hydrophone_sensitivity)
                                                    if hydrophone_sensitivity else "packaged")
    update_summary(directory, "phase", entry)
    rows = [("similarity before compensation", result.similarity_before, None, ""),
            ("similarity after compensation", result.similarity_after, None, ""),
            ("receive − transmit lag before", result.lag_before, None, "s"),
            ("receive − transmit lag after", result.lag_after, None, "s")]
    _write_report(directory / "report_phase.html", "Phase compensation and reciprocity", rows,
                  [("Phase compensation (paper Fig. 10)", phase_figures(result))], [],
                  {"model": str(vt_path), "compensated": result.notes})
    if not quiet:
        typer.echo(f"normalised transmit/receive IR similarity {result.similarity_before:.3f} "
                   f"before, {result.similarity_after:.3f} after compensation; report "
                   f"{directory / 'report_phase.html'}")


@app.command()
def baffle(
    model: Annotated[Path, typer.Argument(help="virtual_transducer.h5")],
    distance: Annotated[float, typer.Option(help="On-axis distance in m.")] = 5e-3,
    report: Annotated[Path | None, typer.Option(
        help="Report page (default: report_baffle.html next to the model).")] = None,
    quiet: Annotated[bool, typer.Option(help="Print nothing.")] = False,
) -> None:
    """Monopole vs dipole source representation by Rayleigh and angular spectrum (paper II C,
    IV C, Fig. 2): one plot of the on-axis field and the largest differences.

    Writes the report page; if the model's directory holds a summary.json, adds a 'baffle'
    entry to it.
    """
    from holoprobe.analysis import analyse_baffle, baffle_figure, update_summary
    from holoprobe.transducer import VirtualTransducer

    vt = VirtualTransducer.load(model)
    result = analyse_baffle(vt, distance=distance)
    out = report if report is not None else model.parent / "report_baffle.html"
    fig, caption = baffle_figure(result)
    d = result.method_difference_percent
    rows = [("distance", distance, None, "m"),
            ("max difference between methods, monopole (%)", d["monopole"], None, ""),
            ("max difference between methods, dipole (%)", d["dipole"], None, ""),
            ("monopole − dipole, whole record (%)", result.representation_difference_percent,
             None, ""),
            ("monopole − dipole, primary wavefront (%)", result.primary_difference_percent,
             None, "")]
    _write_report(out, "Source representation: monopole vs dipole", rows,
                  [("On-axis field (paper Fig. 2)", [(fig, caption)])], result.notes,
                  {"model": str(model), "methods": result.methods})
    if (model.parent / "summary.json").exists():
        entry = result.summary()
        entry["report"] = out.name
        update_summary(model.parent, "baffle", entry)
    if not quiet:
        typer.echo(f"max difference between methods: monopole {d['monopole']:.2f} %, dipole "
                   f"{d['dipole']:.2f} % of the maximum amplitude (paper: 2.1 %, 1.5 %)")
        typer.echo(f"monopole vs dipole: {result.primary_difference_percent:.2f} % on the "
                   f"primary wavefront, {result.representation_difference_percent:.2f} % "
                   "overall (edge waves)")
        for note in result.notes:
            typer.echo(f"note: {note}")
        typer.echo(f"report {out}")
