"""``holoprobe analyse``: the paper's analyses of a characterized probe, as commands.

* ``modes DIR``: spurious antisymmetric modes in the reconstructed surface velocity
  (paper section III D, Fig. 9);
* ``phase DIR``: transmit/receive transfer functions and phase compensation (section IV B,
  Fig. 10);
* ``baffle VT.h5``: monopole vs dipole source representation by Rayleigh, angular spectrum
  and (optionally) k-wave-python (sections II C, IV C, Fig. 2).

``DIR`` is the output directory of ``holoprobe characterize``. Each analysis of a ``DIR``
adds its entry to ``DIR/summary.json`` (atomically; other entries are kept) and its section
to ``DIR/report.html`` (:func:`holoprobe.report.append_report_section`; running it again
replaces the section). Only where there is no ``report.html`` that can take a section
(``characterize --no-report``, or a page written by an older holoprobe) does it write a page
of its own, ``DIR/report_<analysis>.html``; ``summary.json`` says which under
``<analysis>.report``. Values are SI at this boundary too, except where a flag says
otherwise (``--distance`` in m).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Annotated, Any

import typer

from holoprobe.cli._app import VirtualTransducerPath, new_app
from holoprobe.errors import InputError

app = new_app("The paper's analyses: spurious modes, phase compensation, source representation.")


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


#: File name of the characterization report that the analyses add their sections to.
MAIN_REPORT = "report.html"


def _publish(main: Path | None, standalone: Path, *, section_id: str, heading: str,
             title: str, figures: list, rows: list, notes: list[str],
             details: dict[str, Any]) -> tuple[Path, str, str | None]:
    """Add the analysis' section to ``main`` when it is a report that can take one,
    otherwise write the page ``standalone``.

    Returns
    -------
    (path, reference, note)
        The file written, its reference for ``summary.json`` (``report.html#id`` or the
        page's name) and, when ``main`` exists but could not take the section, why.
    """
    from holoprobe.report import append_report_section, build_report

    note = None
    if main is not None and main.is_file():
        try:
            append_report_section(main, heading, figures, parameters=rows, notes=notes,
                                  details=details, section_id=section_id)
            return main, f"{main.name}#{section_id}", None
        except InputError as exc:  # e.g. a page written before sections could be added
            note = f"{main.name} cannot take the section ({exc}); wrote {standalone.name}"
    build_report(standalone, title=title, parameters=rows, sections=[(heading, figures)],
                 warnings=notes, metadata=details, overwrite=True)
    return standalone, standalone.name, note


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
    entry to DIR/summary.json and a section to DIR/report.html (or, without one, writes
    DIR/report_modes.html).
    """
    from holoprobe.analysis import analyse_modes, modes_figures, update_summary
    from holoprobe.io import read_source_velocity

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
    written, reference, note = _publish(
        directory / MAIN_REPORT, directory / "report_modes.html", section_id="analysis-modes",
        heading="Spurious modes of oscillation (paper section III D, Fig. 9)",
        title="Spurious modes of oscillation", figures=modes_figures(result), rows=rows,
        notes=list(result.warnings),
        details={"source": str(directory / "source_velocity.h5"),
                 "aperture": "summary.json" if aperture is not None else "estimated",
                 "criteria": result.criteria})
    entry = result.summary()
    entry["report"] = reference
    entry["aperture_source"] = "summary.json" if aperture is not None else "estimated"
    update_summary(directory, "modes", entry)
    if not quiet:
        verdict = "present" if result.present else "absent"
        freq = (f"{result.frequency / 1e6:.3f} MHz" if math.isfinite(result.frequency)
                else "n/a")
        if note:
            typer.echo(f"note: {note}")
        typer.echo(f"spurious mode {verdict}: tail {freq}, {result.strength_db:.1f} dB re "
                   f"main pulse; report {written}")


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
    entry to DIR/summary.json and a section to DIR/report.html (or, without one, writes
    DIR/report_phase.html).
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
    if vt.receive_impulse_response is None or vt.receive_sampling_rate is None:
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
    rows = [("similarity before compensation", result.similarity_before, None, ""),
            ("similarity after compensation", result.similarity_after, None, ""),
            ("receive − transmit lag before", result.lag_before, None, "s"),
            ("receive − transmit lag after", result.lag_after, None, "s")]
    written, reference, note = _publish(
        directory / MAIN_REPORT, directory / "report_phase.html", section_id="analysis-phase",
        heading="Phase compensation and reciprocity (paper section IV B, Fig. 10)",
        title="Phase compensation and reciprocity", figures=phase_figures(result),
        rows=rows, notes=[], details={"model": str(vt_path), "compensated": result.notes})
    entry = result.summary()
    entry["report"] = reference
    entry["filter"] = None if filt is None else (str(filter_group_delay)
                                                 if filter_group_delay else "BLP-15+ (packaged)")
    entry["hydrophone"] = None if hyd is None else (str(hydrophone_sensitivity)
                                                    if hydrophone_sensitivity else "packaged")
    update_summary(directory, "phase", entry)
    if not quiet:
        if note:
            typer.echo(f"note: {note}")
        typer.echo(f"normalised transmit/receive IR similarity {result.similarity_before:.3f} "
                   f"before, {result.similarity_after:.3f} after compensation; report "
                   f"{written}")


@app.command()
def baffle(
    model: VirtualTransducerPath,
    distance: Annotated[float, typer.Option(help="On-axis distance in m.")] = 5e-3,
    report: Annotated[Path | None, typer.Option(
        help="Write a page of its own here (default: a section of report.html next to the "
             "model, or report_baffle.html there when there is none).")] = None,
    quiet: Annotated[bool, typer.Option(help="Print nothing.")] = False,
) -> None:
    """Monopole vs dipole source representation by Rayleigh, angular spectrum and (with the
    [kwave] extra) k-Wave (paper II C, IV C, Fig. 2): the on-axis field and the differences.

    Adds a section to report.html in the model's directory (the output of 'characterize')
    when there is one, otherwise writes report_baffle.html there (or the page --report);
    if the model's directory holds a summary.json, adds a 'baffle' entry to it.
    """
    from holoprobe.analysis import analyse_baffle, baffle_figure, update_summary
    from holoprobe.transducer import VirtualTransducer

    vt = VirtualTransducer.load(model)
    result = analyse_baffle(vt, distance=distance)
    fig, caption = baffle_figure(result)
    d = result.method_difference_percent
    rows = [("distance", distance, None, "m"),
            ("max difference between methods, monopole (%)", d["monopole"], None, ""),
            ("max difference between methods, dipole (%)", d["dipole"], None, ""),
            *[(f"{rep}: {pair.replace('-', ' vs ')} (%)", value, None, "")
              for rep, pairs in result.pairwise_difference_percent.items()
              for pair, value in pairs.items()],
            ("monopole − dipole, whole record (%)", result.representation_difference_percent,
             None, ""),
            ("monopole − dipole, primary wavefront (%)", result.primary_difference_percent,
             None, "")]
    written, reference, note = _publish(
        model.parent / MAIN_REPORT if report is None else None,
        model.parent / "report_baffle.html" if report is None else report,
        section_id="analysis-baffle",
        heading="Source representation: monopole vs dipole (paper sections II C, IV C, "
                "Fig. 2)",
        title="Source representation: monopole vs dipole", figures=[(fig, caption)],
        rows=rows, notes=list(result.notes),
        details={"model": str(model), "methods": result.methods})
    if (model.parent / "summary.json").exists():
        entry = result.summary()
        entry["report"] = (reference if written.parent.resolve() == model.parent.resolve()
                           else str(written))
        update_summary(model.parent, "baffle", entry)
    if not quiet:
        typer.echo(f"max difference between methods: monopole {d['monopole']:.2f} %, dipole "
                   f"{d['dipole']:.2f} % of the maximum amplitude (paper: 2.1 %, 1.5 %)")
        typer.echo(f"monopole vs dipole: {result.primary_difference_percent:.2f} % on the "
                   f"primary wavefront, {result.representation_difference_percent:.2f} % "
                   "overall (edge waves)")
        for remark in [*result.notes, *([note] if note else [])]:
            typer.echo(f"note: {remark}")
        typer.echo(f"report {written}")
