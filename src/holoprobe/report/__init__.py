"""The characterization report: figures (paper Figs. 3, 5–7, 10a) and ``report.html``.

Figure functions take plain NumPy arrays and floats in SI units and return a
:class:`matplotlib.figure.Figure` (built without ``pyplot``) whose caption is
read with :func:`figure_caption`. :func:`build_report` writes one
self-contained HTML page (parameter table, warnings, figures, provenance),
atomically; :func:`append_report_section` adds (or replaces) a section of figures in
that page, e.g. the results of ``holoprobe analyse``.
"""

from holoprobe.report._figures import (
    CAPTIONS,
    figure_caption,
    plot_aperture_fit,
    plot_array_geometry,
    plot_averaged_rf,
    plot_deconvolution_spectra,
    plot_element_map,
    plot_element_rf,
    plot_hydrophone_deconvolution,
    plot_impulse_response,
    plot_lens_fit,
    plot_mean_velocity,
    plot_orientation,
    plot_plane_amplitude_phase,
    plot_receive_geometry,
    plot_receive_pressure,
    plot_transfer_functions,
)
from holoprobe.report._hologram_figures import (
    plot_aligned_geometry,
    plot_focal_profiles,
    plot_focal_volume,
)
from holoprobe.report._html import (
    DEFAULT_UNITS,
    append_report_section,
    build_report,
    format_quantity,
    summary_html,
)
from holoprobe.report._hydrophone import (
    HYDROPHONE_FILES,
    plot_hydrophone_pulse,
    write_hydrophone_outputs,
)

__all__ = [
    "CAPTIONS",
    "DEFAULT_UNITS",
    "HYDROPHONE_FILES",
    "append_report_section",
    "build_report",
    "figure_caption",
    "format_quantity",
    "plot_aligned_geometry",
    "plot_aperture_fit",
    "plot_array_geometry",
    "plot_averaged_rf",
    "plot_deconvolution_spectra",
    "plot_element_map",
    "plot_element_rf",
    "plot_focal_profiles",
    "plot_focal_volume",
    "plot_hydrophone_deconvolution",
    "plot_hydrophone_pulse",
    "plot_impulse_response",
    "plot_lens_fit",
    "plot_mean_velocity",
    "plot_orientation",
    "plot_plane_amplitude_phase",
    "plot_receive_geometry",
    "plot_receive_pressure",
    "plot_transfer_functions",
    "summary_html",
    "write_hydrophone_outputs",
]
