"""Tests of holoprobe.report: figure functions and the self-contained HTML report."""

from __future__ import annotations

import base64
import html
import io
import re
from html.parser import HTMLParser

import numpy as np
import pytest
from matplotlib.figure import Figure

from holoprobe.errors import InputError
from holoprobe.report import (
    CAPTIONS,
    build_report,
    figure_caption,
    format_quantity,
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

C0 = 1481.0
SMALL = (4.0, 2.5)
UNIT_LABEL = re.compile(r"\S.*(\([^()]*\S[^()]*\)|\[[^\[\]]*\S[^\[\]]*\])")


# ---------------------------------------------------------------- synthetic data


def _pulse(t, t0, f0, cycles):
    """Gaussian-windowed tone burst starting near t0 (s)."""
    sigma = cycles / f0 / 4.0
    centre = t0 + 2.0 * sigma
    return np.exp(-0.5 * ((t - centre) / sigma) ** 2) * np.sin(2 * np.pi * f0 * (t - centre))


def _figures(figsize=SMALL):
    """Every figure function on small synthetic data, keyed by function name."""
    fs = {} if figsize is None else {"figsize": figsize}
    rng = np.random.default_rng(4)
    f0 = 2.5e6
    k = 2 * np.pi * f0 / C0
    # plane: rectangle-like source with a linear phase from a tilt
    x = np.linspace(-15e-3, 15e-3, 41)
    y = np.linspace(-8e-3, 8e-3, 25)
    xx, yy = np.meshgrid(x, y, indexing="ij")
    amp = np.exp(-((xx / 10e-3) ** 8) - (yy / 5e-3) ** 8)
    field = amp * np.exp(1j * k * np.sin(np.radians(0.7)) * xx - 1j * k * yy**2 / (2 * 0.18))
    outline = np.array([[-15e-3, -8e-3], [15e-3, -8e-3], [15e-3, 8e-3], [-15e-3, 8e-3]])
    out = {}
    out["plot_plane_amplitude_phase"] = plot_plane_amplitude_phase(
        field, x, y, title="scan plane", frequency=f0, **fs,
        overlay={"rectangle": (0.1e-3, 0.0, 20e-3, 10e-3), "points": [(0.3e-3, -0.1e-3)],
                 "outline": outline},
    )
    prof_x = np.abs(field[:, 12]) + 0.01 * rng.standard_normal(x.size)
    prof_y = np.abs(field[20, :]) + 0.01 * rng.standard_normal(y.size)
    out["plot_aperture_fit"] = plot_aperture_fit(
        x, prof_x, np.abs(field[:, 12]), y, prof_y, np.abs(field[20, :]),
        width=20e-3, height=10e-3, center_x=0.1e-3, center_y=0.0, **fs,
    )
    focus, h = 0.18, 14e-3
    model = ((h / 2) ** 2 - y**2) / (2 * focus * C0)
    measured = model[None, :] + 2e-9 * rng.standard_normal((5, y.size))
    out["plot_lens_fit"] = plot_lens_fit(y, measured, model, focus=focus,
                                         weights=np.abs(field[::8, :])[:5], **fs)
    t = np.arange(400) / 50e6
    velocity = 3e3 * _pulse(t, 2e-6, f0, 2) + 20 * rng.standard_normal(t.size)
    out["plot_mean_velocity"] = plot_mean_velocity(t, velocity, 2e-6, threshold=100.0,
                                                   **fs)
    ir = _pulse(t, 0.2e-6, f0, 3) * 1e11
    freq = np.fft.rfftfreq(t.size, t[1] - t[0])
    spec = 20 * np.log10(np.abs(np.fft.rfft(ir)) / np.abs(np.fft.rfft(ir)).max() + 1e-12)
    out["plot_impulse_response"] = plot_impulse_response(
        t, ir, freq, spec, label="transmit", unit="Pa/(V·s)", peak_frequency=f0,
        band=(1.6e6, 3.4e6), max_frequency=8e6, **fs,
    )
    kx = np.linspace(-2 * k, 2 * k, 48)
    ky = np.linspace(-2 * k, 2 * k, 40)
    kxx, kyy = np.meshgrid(kx, ky, indexing="ij")
    spec_k = -((kxx - 0.1 * k) ** 2 + kyy**2) / k**2 * 20
    s = np.linspace(-k, k, 50)
    out["plot_orientation"] = plot_orientation(
        kx, ky, spec_k, [np.column_stack([0.1 * k + 0.05 * s, s]), np.column_stack([s, 0 * s])],
        wavenumber=k, angles_deg=(6.04, 9.01, 2.99), **fs,
    )
    tilt = np.radians(3.0)
    out["plot_receive_geometry"] = plot_receive_geometry(
        source=(0.0, 0.0, 28e-3, 0.0), scan_plane=(0.0, 3.6e-3, 36e-3, 0.01),
        reflector=(0.0, 45e-3, 50e-3, tilt / 2), sensor=(2.5e-3, 89.7e-3, 28e-3, tilt),
        path=[(0.0, 0.0), (1.2e-3, 45e-3), (2.5e-3, 89.7e-3)], **fs,
    )
    n_el = 24
    t_rx = 58e-6 + np.arange(300) / 25e6
    arrival = 60.7e-6 + 3e-9 * np.arange(n_el)
    rf = np.stack([_pulse(t_rx, a, f0, 2) for a in arrival]) + 0.02 * rng.standard_normal(
        (n_el, t_rx.size))
    measured_arrival = arrival + 1e-9 * rng.standard_normal(n_el)
    measured_arrival[:2] = np.nan
    out["plot_element_rf"] = plot_element_rf(t_rx, rf, measured_arrival, arrival,
                                             **fs)
    amp = 1 + 0.05 * rng.standard_normal(n_el)
    amp[[0, 9]] = 0.01
    out["plot_element_map"] = plot_element_map(
        amp, 8e-9 * rng.standard_normal(n_el), dead=[0, 9], weak=[5],
        amplitude_uncertainty=np.full(n_el, 0.01), receive_gain=amp[::-1], **fs)
    from holoprobe.geometry import ArrayGeometry

    arc = ArrayGeometry.convex(n_el, 0.5e-3, 8e-3, 0.45e-3, 5e-3)
    out["plot_array_geometry"] = plot_array_geometry(arc.positions, arc.normals, amp,
                                                     widths=arc.widths, dead=[0, 9], **fs)
    out["plot_averaged_rf"] = plot_averaged_rf(t_rx, rf.mean(axis=0), 60.7e-6, threshold=0.05,
                                               **fs)
    out["plot_receive_pressure"] = plot_receive_pressure(t_rx, 1e3 * rf, **fs)
    f = np.linspace(0, 8e6, 81)
    bump = -(((f - f0) / 1e6) ** 2) * 6
    out["plot_deconvolution_spectra"] = plot_deconvolution_spectra(
        f, bump, bump - 3, bump + 3, band=(1.5e6, 3.7e6), **fs,
    )
    ht = np.exp(-(((f - 2.55e6) / 1e6) ** 2)) * np.exp(-2j * np.pi * f * 0.5e-6)
    hr = np.exp(-(((f - 2.6e6) / 1.1e6) ** 2)) * np.exp(-2j * np.pi * f * 0.4e-6)
    out["plot_transfer_functions"] = plot_transfer_functions(f, ht, hr, **fs)
    t_h = np.arange(512) / 100e6
    v_h = 1e-3 * _pulse(t_h, 1e-6, f0, 3)
    f_h = np.fft.rfftfreq(t_h.size, t_h[1] - t_h[0])
    db_h = 20 * np.log10(np.abs(np.fft.rfft(v_h)) / np.abs(np.fft.rfft(v_h)).max() + 1e-12)
    out["plot_hydrophone_deconvolution"] = plot_hydrophone_deconvolution(
        t_h, v_h, 2e4 * v_h / 1e-3 * 1e-1, np.full(t_h.size, 3e2), f_h, db_h, db_h - 1.0,
        np.linspace(1e6, 20e6, 20), np.full(20, -260.0), cutoff_hz=15e6, **fs,
    )
    return out


@pytest.fixture(scope="module")
def figures():
    return _figures()


# ---------------------------------------------------------------- figures


def test_every_figure_function_is_exercised(figures):
    assert set(figures) == set(CAPTIONS)


def test_every_axis_of_every_figure_is_labelled_with_a_unit(figures):
    for name, fig in figures.items():
        assert isinstance(fig, Figure), name
        assert fig.axes, name
        for ax in fig.axes:
            if hasattr(ax, "_colorbar"):
                long_axis = ax._colorbar.long_axis
                labels = [long_axis.get_label_text()]
            else:
                labels = [ax.get_xlabel(), ax.get_ylabel()]
            for label in labels:
                assert UNIT_LABEL.fullmatch(label.strip()), f"{name}: label {label!r}"


def test_every_figure_carries_its_caption(figures):
    for name, fig in figures.items():
        assert figure_caption(fig).startswith(CAPTIONS[name]), name


def test_figures_do_not_register_with_pyplot():
    import matplotlib.pyplot as plt

    before = set(plt.get_fignums())
    _figures()
    assert set(plt.get_fignums()) == before


def test_plane_axes_are_in_mm_with_pixel_centres_on_the_samples():
    x = np.array([-2e-3, -1e-3, 0.0, 1e-3, 2e-3])
    y = np.array([-1e-3, 0.0, 1e-3])
    field = np.ones((5, 3), complex)
    field[4, 0] = 2.0  # the maximum, at x = 2 mm, y = -1 mm
    fig = plot_plane_amplitude_phase(field, x, y, title="t", frequency=2.5e6, figsize=SMALL)
    image = fig.axes[0].images[0]
    # pixel pitch 1 mm: edges half a pixel outside the first and last sample
    assert image.get_extent() == pytest.approx([-2.5, 2.5, -1.5, 1.5])
    data = np.asarray(image.get_array())
    assert data.shape == (3, 5)  # rows are y (origin lower), columns x
    assert data[0, 4] == pytest.approx(0.0)  # 0 dB at the maximum
    assert data[1, 1] == pytest.approx(20 * np.log10(0.5))
    assert "2.5 MHz" in figure_caption(fig)


def test_plane_overlay_rectangle_is_drawn_at_the_fitted_aperture_in_mm():
    x = np.linspace(-5e-3, 5e-3, 11)
    y = np.linspace(-3e-3, 3e-3, 7)
    fig = plot_plane_amplitude_phase(np.ones((11, 7)), x, y, title="source", frequency=2e6,
                                     overlay={"rectangle": (1e-3, -0.5e-3, 6e-3, 2e-3)},
                                     figsize=SMALL)
    rect = fig.axes[0].patches[0]
    assert rect.get_xy() == pytest.approx((-2.0, -1.5))
    assert (rect.get_width(), rect.get_height()) == pytest.approx((6.0, 2.0))
    with pytest.raises(InputError, match="overlay"):
        plot_plane_amplitude_phase(np.ones((11, 7)), x, y, title="s", frequency=2e6,
                                   overlay={"circle": 1})


def test_aperture_and_lens_captions_state_the_fit_in_mm():
    x = np.linspace(-20e-3, 20e-3, 9)
    y = np.linspace(-10e-3, 10e-3, 7)
    fig = plot_aperture_fit(x, np.ones(9), np.ones(9), y, np.ones(7), np.ones(7),
                            width=28.54e-3, height=14.28e-3, center_x=-0.31e-3,
                            center_y=-0.06e-3, figsize=SMALL)
    assert "W = 28.54 mm, H = 14.28 mm" in figure_caption(fig)
    edges = sorted(line.get_xdata()[0] for line in fig.axes[0].lines[2:])
    assert edges == pytest.approx([-0.31 - 14.27, -0.31 + 14.27])
    fig = plot_lens_fit(y, np.zeros(7), 1e-9 * np.arange(7), focus=0.181, figsize=SMALL)
    assert "F = 181.0 mm" in figure_caption(fig)
    assert fig.axes[0].lines[-1].get_ydata() == pytest.approx(np.arange(7.0))  # ns
    fig = plot_lens_fit(y, np.zeros(7), np.zeros(7), focus=np.inf, figsize=SMALL)
    assert "F = ∞" in figure_caption(fig)


def test_time_and_frequency_axes_are_in_microseconds_and_megahertz(figures):
    t = np.arange(100) / 50e6  # 0 .. 1.98 µs
    f = np.linspace(0, 10e6, 11)
    fig = plot_impulse_response(t, np.sin(t * 1e7), f, -np.abs(f - 3e6) / 1e5,
                                label="receive", unit="V/(Pa·s)", peak_frequency=3e6,
                                band=(2.9e6, 3.1e6), figsize=SMALL)
    assert fig.axes[0].lines[0].get_xdata()[-1] == pytest.approx(1.98)
    assert fig.axes[1].lines[0].get_xdata()[-1] == pytest.approx(10.0)
    assert "peak 3.00 MHz" in figure_caption(fig)
    assert "2.90–3.10 MHz" in figure_caption(fig)
    fig = plot_mean_velocity(t, np.sin(t * 1e7), 0.5e-6, figsize=SMALL)
    marker = fig.axes[0].lines[1]
    assert marker.get_xdata()[0] == pytest.approx(0.5)
    assert marker.get_ydata()[0] == pytest.approx(np.sin(0.5e-6 * 1e7), abs=2e-3)


def test_transfer_functions_are_normalised_to_zero_db():
    f = np.linspace(0, 5e6, 51)
    ht = 7.0 * np.exp(-(((f - 2e6) / 1e6) ** 2))
    hr = 0.003 * np.exp(-(((f - 3e6) / 1e6) ** 2))
    fig = plot_transfer_functions(f, ht, hr, floor_db=-30.0, figsize=SMALL)
    for line in fig.axes[0].lines:
        level = np.asarray(line.get_ydata())
        assert level.max() == pytest.approx(0.0)
        assert level.min() >= -30.0
    assert "transmit 2.00 MHz, receive 3.00 MHz" in figure_caption(fig)
    assert fig.axes[1].get_ylabel() == "normalised magnitude (1)"  # magnitudes: no phase


def test_element_rf_image_and_arrival_line_share_the_element_axis():
    t = np.arange(50) / 10e6
    rf = np.zeros((6, 50))
    line = 1e-6 + 0.1e-6 * np.arange(6)
    fig = plot_element_rf(t, rf, line, line, figsize=SMALL)
    ax = fig.axes[0]
    assert ax.images[0].get_extent()[:2] == pytest.approx([0.5, 6.5])
    assert ax.lines[1].get_xdata() == pytest.approx(np.arange(1, 7))
    assert ax.lines[1].get_ydata() == pytest.approx(1e6 * line)
    assert "100.000 ns per element" in figure_caption(fig)


def test_figure_functions_name_the_wrong_argument():
    t = np.arange(10.0)
    with pytest.raises(InputError, match="signal"):
        plot_mean_velocity(t, np.zeros(9), 0.0)
    with pytest.raises(InputError, match="field_2d"):
        plot_plane_amplitude_phase(np.zeros((3, 4)), np.arange(4.0), np.arange(3.0),
                                   title="t", frequency=1e6)
    with pytest.raises(InputError, match="band"):
        plot_impulse_response(t, t, t, t, label="x", unit="u", peak_frequency=1.0,
                              band=(3.0, 1.0))
    with pytest.raises(InputError, match="fitted_line"):
        plot_element_rf(t, np.zeros((4, 10)), np.zeros(4), np.zeros(3))
    with pytest.raises(InputError, match="sensor"):
        plot_receive_geometry(source=(0, 0, 1, 0), scan_plane=(0, 0, 1, 0),
                              reflector=(0, 0, 1, 0), sensor=(0, 0, 1))
    with pytest.raises(InputError, match="onset"):
        plot_averaged_rf(t, t, float("nan"))


# ---------------------------------------------------------------- quantities


def test_quantities_are_shown_with_si_prefixes_and_matching_decimals():
    assert format_quantity(0.02854, 3.1e-5, "m") == "28.540 ± 0.031 mm"
    assert format_quantity(0.181, None, "m") == "181 mm"
    assert format_quantity(2.55e6, None, "Hz") == "2.55 MHz"
    assert format_quantity(60.704e-6, 2e-9, "s") == "60.7040 ± 0.0020 µs"
    assert format_quantity(6.04, 0.012, "°") == "(6.040 ± 0.012)°"
    assert format_quantity(96, None, "") == "96"
    assert format_quantity(0.78, float("nan"), "") == "0.78"
    assert format_quantity(9.5337e10, None, "Pa/(V·s)") == "9.5337e+10 Pa/(V·s)"
    assert format_quantity("n/a", 1.0, "m") == "n/a"


# ---------------------------------------------------------------- html report


class _TagChecker(HTMLParser):
    VOID = frozenset({"meta", "img", "br", "hr", "link", "input", "col", "source", "wbr"})

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.stack, self.errors, self.srcs, self.hrefs, self.tags = [], [], [], [], []
        self.text = []

    def handle_starttag(self, tag, attrs):
        self.tags.append(tag)
        attrs = dict(attrs)
        if "src" in attrs:
            self.srcs.append(attrs["src"])
        if "href" in attrs:
            self.hrefs.append(attrs["href"])
        if tag not in self.VOID:
            self.stack.append(tag)

    def handle_endtag(self, tag):
        if not self.stack or self.stack[-1] != tag:
            self.errors.append(f"unbalanced </{tag}>, open: {self.stack[-3:]}")
        else:
            self.stack.pop()

    def handle_data(self, data):
        self.text.append(data)


def _small_figure(label="x"):
    fig = Figure(figsize=(2.0, 1.5))
    ax = fig.add_subplot()
    ax.plot([0, 1], [0, 1])
    ax.set_xlabel(f"{label} (mm)")
    return fig


def test_report_is_one_self_contained_escaped_html_file(tmp_path):
    captions = ["Aperture <fit> & W = 28.5 mm", "Lens \"fit\" 'F'"]
    parameters = [
        ("aperture width <W>", 0.02854, 3e-5, "m"),
        ("lens focus F", 0.181, 0.004, "m"),
        ("onset t0", 2.01e-6, None, "s"),
        ("count & pitch", 96, None, ""),
    ]
    warnings = ["scan not Nyquist sampled: dx > λ/2 <at 3.7 MHz>", "field at edge & clipped"]
    out = build_report(
        tmp_path / "report.html", title="P4-1 <test> & report", parameters=parameters,
        sections=[("Transmit <Fig. 6>", [(_small_figure("a"), captions[0]),
                                          (_small_figure("b"), captions[1])]),
                  ("Receive", [plot_mean_velocity(np.arange(5.0), np.arange(5.0), 1.0,
                                                  figsize=(2, 1.5))])],
        warnings=warnings,
        metadata={"scan": "scan.h5", "sha256": "ab" * 32, "config": {"iterations": 2}},
        dpi=40,
    )
    assert out == tmp_path / "report.html"
    assert [p.name for p in tmp_path.iterdir()] == ["report.html"]
    text = out.read_text(encoding="utf-8")
    for s in [*captions, *warnings, *(p[0] for p in parameters), "Transmit <Fig. 6>"]:
        assert html.escape(s, quote=True) in text, s
        if "<" in s:
            assert s not in text
    assert CAPTIONS["plot_mean_velocity"] in text  # bare Figure: its own caption
    assert "28.540 ± 0.030 mm" in text and "181.0 ± 4.0 mm" in text
    assert "ab" * 32 in text and "&quot;iterations&quot;: 2" in text
    assert not re.search(r"https?:", text, flags=re.IGNORECASE)
    checker = _TagChecker()
    checker.feed(text)
    checker.close()
    assert checker.errors == [] and checker.stack == []
    assert "script" not in checker.tags and "link" not in checker.tags
    assert all(h.startswith("#") for h in checker.hrefs)
    assert len(checker.srcs) == 3
    for src in checker.srcs:
        assert src.startswith("data:image/png;base64,")
        assert base64.b64decode(src.split(",", 1)[1])[:8] == b"\x89PNG\r\n\x1a\n"
    body = "".join(checker.text)
    assert body.index(warnings[0]) < body.index("aperture width <W>")  # warnings first


def test_report_from_summary_dict_pairs_values_with_uncertainties_and_units(tmp_path):
    summary = {
        "scan_plane": {"theta_x_deg": 0.5, "z0": 3.57e-3},
        "aperture": {"width": 0.02854, "height": 0.01428},
        "transmit": {"peak_frequency": 2.55e6, "onset": 1.2e-7},
        "custom": {"gain": (3.0, 0.25, "dB")},
        "uncertainty": {"scan_plane": {"theta_x_deg": 0.0021, "z0": 2e-6},
                        "aperture": {"width": 3.1e-5}},
        "warnings": ["should not be a parameter row"],
    }
    out = build_report(tmp_path / "r.html", title="t", parameters=summary, sections=[],
                       warnings=[], timestamp=False)
    text = out.read_text(encoding="utf-8")
    for s in ["(0.5000 ± 0.0021)°", "3.5700 ± 0.0020 mm", "28.540 ± 0.031 mm",
              "14.28 mm", "2.55 MHz", "120 ns", "3.00 ± 0.25 dB",
              "theta_x_deg", "peak_frequency", "No warnings."]:
        assert s in text, s
    assert "should not be a parameter row" not in text
    assert "report generated" not in text


def test_failure_while_writing_leaves_no_partial_file(tmp_path):
    class Broken(Figure):
        def draw(self, renderer):
            raise RuntimeError("renderer failed")

    target = tmp_path / "report.html"
    with pytest.raises(RuntimeError, match="renderer failed"):
        build_report(target, title="t", parameters=[("a", 1.0, None, "m")],
                     sections=[("s", [(_small_figure(), "ok"), (Broken(), "broken")])],
                     warnings=[], dpi=30)
    assert list(tmp_path.iterdir()) == []
    target.write_text("previous report")
    with pytest.raises(RuntimeError):
        build_report(target, title="t", sections=[("s", [(Broken(), "broken")])],
                     overwrite=True)
    assert target.read_text() == "previous report"
    assert [p.name for p in tmp_path.iterdir()] == ["report.html"]


def test_report_refuses_to_overwrite_unless_asked(tmp_path):
    target = tmp_path / "report.html"
    target.write_text("old")
    with pytest.raises(InputError, match="exists"):
        build_report(target, title="t")
    assert target.read_text() == "old"
    build_report(target, title="new <t>", overwrite=True)
    assert "new &lt;t&gt;" in target.read_text(encoding="utf-8")


def test_report_rejects_malformed_input_before_writing(tmp_path):
    with pytest.raises(InputError, match="parameters"):
        build_report(tmp_path / "r.html", title="t", parameters=[("a", 1.0, "m")])
    with pytest.raises(InputError, match="sections"):
        build_report(tmp_path / "r.html", title="t", sections=[("s", ["not a figure"])])
    assert list(tmp_path.iterdir()) == []


def test_deconvolution_spectra_are_clipped_to_the_dynamic_range():
    f = np.linspace(0, 8e6, 81)  # 0.1 MHz steps: 2.5 MHz is a sample, the peak is 0 dB
    y = -((f - 2.5e6) / 0.2e6) ** 2  # falls to about -760 dB at 8 MHz
    fig = plot_deconvolution_spectra(f, y, y - 10, y + 4, dynamic_range_db=70.0, figsize=SMALL)
    assert fig.axes[0].get_ylim() == pytest.approx((4.0 - 70.0, 9.0))
    with pytest.raises(InputError, match="P_db"):
        plot_deconvolution_spectra(f, y, y[:-1], y)


# ------------------------------------------------------------- added sections


def _base_report(path):
    return build_report(path, title="t", parameters=[("a", 1.0, None, "m")],
                        sections=[("Transmit", [(_small_figure("a"), "first"),
                                                (_small_figure("b"), "second")])],
                        warnings=[], dpi=30, timestamp=False)


def _parse(text):
    checker = _TagChecker()
    checker.feed(text)
    checker.close()
    assert checker.errors == [] and checker.stack == []
    return checker


def test_added_section_appears_once_in_page_and_contents_with_embedded_images(tmp_path):
    from holoprobe.report import append_report_section

    out = _base_report(tmp_path / "report.html")
    caption = "Modes <odd> & \"even\": look for a tail"
    append_report_section(out, "Spurious modes <Fig. 9>",
                          [(_small_figure("c"), caption), (_small_figure("d"), "more")],
                          parameters=[("tail frequency", 3.3e6, None, "Hz")],
                          notes=["weak <tail>"], details={"source": "v.h5"}, dpi=30)
    assert [p.name for p in tmp_path.iterdir()] == ["report.html"]
    text = out.read_text(encoding="utf-8")
    checker = _parse(text)
    heading = html.escape("Spurious modes <Fig. 9>")
    assert text.count(f"<h2>{heading}</h2>") == 1
    assert "Spurious modes <Fig. 9>" not in text and "weak &lt;tail&gt;" in text
    assert html.escape(caption, quote=True) in text and "3.3 MHz" in text
    # the contents link to the new section, which comes after the old ones, before
    # the provenance
    assert "#sec-spurious-modes-fig-9" in checker.hrefs
    assert checker.hrefs.index("#sec-spurious-modes-fig-9") < checker.hrefs.index(
        "#provenance")
    assert text.count('<section id="sec-spurious-modes-fig-9">') == 1
    assert text.index("<h2>Transmit</h2>") < text.index(f"<h2>{heading}") < text.index(
        "<h2>Provenance</h2>")
    # self-contained: 2 + 2 PNGs as data: URIs, figures numbered on, count updated
    assert len(checker.srcs) == 4
    for src in checker.srcs:
        assert src.startswith("data:image/png;base64,")
        assert base64.b64decode(src.split(",", 1)[1])[:8] == b"\x89PNG\r\n\x1a\n"
    assert not re.search(r"https?:", text, flags=re.IGNORECASE)
    numbers = re.findall(r"Figure (\d+)\.", "".join(checker.text))
    assert numbers == ["1", "2", "3", "4"]
    assert "4<!-- /hp:figure-count --> figures" in text


def test_rerunning_an_added_section_replaces_it_in_place(tmp_path):
    from holoprobe.report import append_report_section

    out = _base_report(tmp_path / "report.html")
    append_report_section(out, "Modes", [(_small_figure(), "modes v1"),
                                         (_small_figure(), "modes v1 bis")], dpi=30)
    append_report_section(out, "Phase", [(_small_figure(), "phase")], dpi=30)
    append_report_section(out, "Modes", [(_small_figure(), "modes v2")], dpi=30)
    text = out.read_text(encoding="utf-8")
    checker = _parse(text)
    assert text.count("<h2>Modes</h2>") == 1 and text.count("<h2>Phase</h2>") == 1
    assert "modes v1" not in text and "modes v2" in text
    assert checker.hrefs.count("#sec-modes") == 1 and checker.hrefs.count("#sec-phase") == 1
    assert text.index("<h2>Modes</h2>") < text.index("<h2>Phase</h2>")  # kept its place
    body = "".join(checker.text)
    assert re.findall(r"Figure (\d+)\.", body) == ["1", "2", "3", "4"]
    assert body.index("Figure 3. modes v2") < body.index("Figure 4. phase")
    assert len(checker.srcs) == 4 and "4<!-- /hp:figure-count -->" in text
    with pytest.raises(InputError, match="replace"):
        append_report_section(out, "Modes", [_small_figure()], replace=False)
    # an explicit id finds the section whatever its heading
    append_report_section(out, "Phase (again)", [], section_id="sec-phase")
    text = out.read_text(encoding="utf-8")
    assert "<h2>Phase</h2>" not in text and text.count("Phase (again)") == 2  # h2 + toc


def test_failed_addition_leaves_the_report_unchanged(tmp_path, monkeypatch):
    from holoprobe.report import _html, append_report_section

    class Broken(Figure):
        def draw(self, renderer):
            raise RuntimeError("renderer failed")

    out = _base_report(tmp_path / "report.html")
    original = out.read_bytes()
    with pytest.raises(RuntimeError, match="renderer failed"):
        append_report_section(out, "s", [(_small_figure(), "ok"), (Broken(), "broken")])
    assert out.read_bytes() == original

    def half_then_fail(path, text):  # the disk fills up half-way through the write
        with open(path, "w", encoding="utf-8") as fh:
            fh.write(text[: len(text) // 2])
        raise OSError("no space left on device")

    monkeypatch.setattr(_html, "_write_text", half_then_fail)
    with pytest.raises(OSError, match="no space"):
        append_report_section(out, "s", [(_small_figure(), "ok")], dpi=30)
    assert out.read_bytes() == original
    assert [p.name for p in tmp_path.iterdir()] == ["report.html"]


def test_adding_to_a_missing_or_foreign_page_is_an_input_error(tmp_path):
    from holoprobe.report import append_report_section

    with pytest.raises(InputError, match="no report"):
        append_report_section(tmp_path / "report.html", "s", [])
    foreign = tmp_path / "foreign.html"
    foreign.write_text("<html><body><h2>s</h2></body></html>")
    with pytest.raises(InputError, match="build_report"):
        append_report_section(foreign, "s", [])
    assert foreign.read_text() == "<html><body><h2>s</h2></body></html>"
    out = _base_report(tmp_path / "report.html")
    for bad in ("parameters", "1abc", "a b", "x<y"):
        with pytest.raises(InputError, match="section_id"):
            append_report_section(out, "s", [], section_id=bad)
    with pytest.raises(InputError, match="figures"):
        append_report_section(out, "s", ["not a figure"])
    with pytest.raises(InputError, match="heading"):
        append_report_section(out, "  ", [])



def test_embedded_png_is_savefigs_png_drawn_once():
    """The report draws each figure once (Agg canvas, layout included); the bytes are
    those ``savefig`` writes (which draws a constrained-layout figure twice), and the
    figure's dpi, face colour and canvas are left as they were."""
    from holoprobe._png import PNG_COMPRESS_LEVEL
    from holoprobe.report._html import _png_bytes

    draws: list[int] = []

    class Counting(Figure):
        def draw(self, renderer):
            draws.append(1)
            super().draw(renderer)

    def make() -> Figure:
        fig = Counting(figsize=(5.0, 3.0), layout="constrained", facecolor="0.9")
        ax1, ax2 = fig.subplots(1, 2)
        image = ax1.imshow(np.outer(np.hanning(40), np.hanning(30)), aspect="auto")
        fig.colorbar(image, ax=ax1, label="pressure (Pa)")
        ax2.plot(np.linspace(0, 1, 50), np.sin(np.linspace(0, 6, 50)), label="sine")
        ax2.set(xlabel="time (µs)", ylabel="velocity (mm/s)", title="a title")
        ax2.legend()
        return fig

    reference = io.BytesIO()
    make().savefig(reference, format="png", dpi=110, metadata={"Software": None},
                   facecolor="white", pil_kwargs={"compress_level": PNG_COMPRESS_LEVEL})
    assert len(draws) == 2
    fig = make()
    canvas = fig.canvas
    assert _png_bytes(fig, 110) == reference.getvalue()
    assert len(draws) == 3
    assert fig.dpi == 100 and fig.canvas is canvas
    assert fig.get_facecolor() == pytest.approx((0.9, 0.9, 0.9, 1.0))


def _inside_canvas(fig: Figure) -> bool:
    """Whether everything drawn (tick labels, axis labels, titles, colour bars, legends)
    lies on the canvas: a fixed-layout figure whose margins are too narrow would cut it."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    box = fig.get_tightbbox(canvas.get_renderer())
    w, h = fig.get_size_inches()
    tol = 1.0 / fig.dpi  # one pixel
    return box.x0 >= -tol and box.y0 >= -tol and box.x1 <= w + tol and box.y1 <= h + tol


def test_report_figures_at_their_own_size_are_drawn_whole_without_a_layout_engine():
    """At their default sizes the figures use fixed margins (no layout engine: ≈ 40 %
    less CPU to draw) and nothing is cut off the canvas."""
    fixed = {"plot_plane_amplitude_phase", "plot_aperture_fit", "plot_lens_fit",
             "plot_mean_velocity", "plot_impulse_response", "plot_orientation",
             "plot_receive_geometry", "plot_element_rf", "plot_element_map",
             "plot_averaged_rf", "plot_receive_pressure", "plot_deconvolution_spectra",
             "plot_transfer_functions"}
    for name, fig in _figures(None).items():
        if name in fixed:
            assert fig.get_layout_engine() is None, name
        assert _inside_canvas(fig), name


def test_tick_labels_wider_than_the_fixed_margins_get_the_constrained_layout():
    t = np.arange(400) / 50e6
    ok = plot_mean_velocity(t, 3e4 * _pulse(t, 2e-6, 2.5e6, 2), 2e-6)  # "−30000"
    assert ok.get_layout_engine() is None and _inside_canvas(ok)
    wide = plot_mean_velocity(t, 3e5 * _pulse(t, 2e-6, 2.5e6, 2), 2e-6)  # "−300000"
    assert wide.get_layout_engine() is not None and _inside_canvas(wide)
    rf = np.outer(np.hanning(8), _pulse(t, 2e-6, 2.5e6, 2)) * 3e5  # colour bar "−300000"
    wide_bar = plot_element_rf(t, rf, np.full(8, 2.2e-6), np.full(8, 2.2e-6))
    assert wide_bar.get_layout_engine() is not None and _inside_canvas(wide_bar)
    tiny = plot_mean_velocity(t, 3e4 * _pulse(t, 2e-6, 2.5e6, 2), 2e-6, figsize=(1.5, 1.2))
    assert tiny.get_layout_engine() is not None  # margins too wide for the figure


def test_lens_fit_draws_every_measured_row_as_its_own_polyline_in_ns():
    y = np.linspace(-7e-3, 7e-3, 15)
    rows = np.stack([1e-9 * (k + 1) + 1e-12 * y * 1e3 for k in range(4)])
    fig = plot_lens_fit(y, rows, rows.mean(axis=0), focus=0.18)
    grey = [ln for ln in fig.axes[0].get_lines() if ln.get_color() == "0.75"]
    assert len(grey) == 1  # one artist, the rows separated by NaN gaps
    xs, ys = np.asarray(grey[0].get_xdata()), np.asarray(grey[0].get_ydata())
    pieces = np.split(np.arange(xs.size), np.flatnonzero(np.isnan(ys)) + 1)
    drawn = [(xs[i][~np.isnan(ys[i])], ys[i][~np.isnan(ys[i])]) for i in pieces if i.size > 1]
    assert len(drawn) == 4
    for (x_mm, d_ns), row in zip(drawn, rows, strict=True):
        np.testing.assert_allclose(x_mm, y * 1e3)
        np.testing.assert_allclose(d_ns, row * 1e9)


@pytest.mark.parametrize("scale", [1e-3, 12345.0, 99999.0, 3e5])
def test_figures_of_any_magnitude_are_drawn_whole(scale):
    """Tick labels from 0.0010 to −100000 (fixed margins or the constrained fallback)
    and a long list of dead elements stay on the canvas."""
    t = np.arange(400) / 50e6
    s = scale * _pulse(t, 2e-6, 2.5e6, 2)
    y = np.linspace(-5e-3, 5e-3, 30)
    figs = [
        plot_mean_velocity(t, s, 2e-6),
        plot_impulse_response(t, s, np.linspace(0, 8e6, 100), np.linspace(-80, 0, 100),
                              label="receive", unit="ADCL/Pa", peak_frequency=2.5e6,
                              band=(1e6, 4e6)),
        plot_element_rf(t, np.outer(np.hanning(64), s), np.full(64, 2.3e-6),
                        np.full(64, 2.3e-6), unit="ADCL"),
        plot_lens_fit(y, scale * 1e-9 * np.stack([np.hanning(30)] * 3),
                      scale * 1e-9 * np.hanning(30), focus=0.05),
        plot_aperture_fit(y, scale * np.hanning(30), scale * np.hanning(30), y,
                          scale * np.hanning(30), scale * np.hanning(30), width=8e-3,
                          height=8e-3, center_x=0.0, center_y=0.0),
        plot_element_map(np.ones(128), scale * 1e-12 * np.sin(np.arange(128)),
                         dead=list(range(0, 128, 9)), weak=[3, 5]),
    ]
    for fig in figs:
        assert _inside_canvas(fig), (scale, figure_caption(fig)[:40])
