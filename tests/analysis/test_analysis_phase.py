"""Phase compensation (paper section IV B): Bode minimum phase against an analytic
low-pass, compensation of IRs delayed by known filters, and the command on a small model."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from typer.testing import CliRunner

from holoprobe.analysis import (
    analyse_phase,
    default_filter_phase,
    hydrophone_phase,
    phase_figures,
)
from holoprobe.cli.analyse import app
from holoprobe.signal import filter_phase_from_group_delay
from holoprobe.transducer import VirtualTransducer

FS = 250e6


def pulse(t: np.ndarray, fc: float = 2.5e6, sigma: float = 0.15e-6) -> np.ndarray:
    return np.exp(-0.5 * (t / sigma) ** 2) * np.cos(2 * np.pi * fc * t)


@pytest.mark.parametrize("extrapolation", ["constant", "slope"])
def test_minimum_phase_of_first_order_lowpass_is_minus_arctan(extrapolation):
    f0 = 5e6
    f = np.geomspace(1e3, 5e9, 400)
    mag = 1 / np.sqrt(1 + (f / f0) ** 2)
    at = np.geomspace(0.1 * f0, 10 * f0, 50)
    phi = hydrophone_phase((f, mag), at, extrapolation=extrapolation, convention="fft")
    truth = -np.arctan(at / f0)
    np.testing.assert_allclose(phi, truth, rtol=0.01)
    # holoprobe's conjugate convention is the opposite sign
    np.testing.assert_allclose(hydrophone_phase((f, mag), at, extrapolation=extrapolation),
                               -phi)


def test_transmit_ir_behind_a_minimum_phase_lowpass_is_recovered():
    # the measured transmit IR is the true one convolved (in time, causally) with a
    # first-order low-pass g(t) = ω0 e^{−ω0 t}: a minimum-phase system
    f0 = 4e6
    w0 = 2 * np.pi * f0
    n = 1000
    t = np.arange(n) / FS
    truth = pulse(t - 1.0e-6)
    g = w0 * np.exp(-w0 * t) / FS
    g[0] *= 0.5  # trapezoid rule for the convolution integral (the jump of g at t = 0)
    measured = np.convolve(truth, g)[:n]
    f = np.geomspace(1e3, 5e9, 400)
    calib = (f, 1 / np.sqrt(1 + (f / f0) ** 2))
    r = analyse_phase(measured, FS, measured, FS, hydrophone=calib, duration=None,
                      remove_mean=False)
    # phase removed; the amplitude of the low-pass (not compensated) stays: compare with
    # the truth filtered by the zero-phase |G|
    spec = np.fft.rfft(truth, 4 * n)
    fz = np.fft.rfftfreq(4 * n, 1 / FS)
    expected = np.fft.irfft(spec / np.sqrt(1 + (fz / f0) ** 2), 4 * n)[:n]
    err = np.max(np.abs(r.transmit_compensated - expected)) / np.max(np.abs(expected))
    assert err < 0.02
    before = np.max(np.abs(measured - expected)) / np.max(np.abs(expected))
    assert before > 10 * err


def test_filter_group_delay_is_removed_from_transmit_and_restored_in_receive():
    tau0 = 60e-9
    n = 600
    t = np.arange(n) / FS
    truth = pulse(t - 1.0e-6)
    filt = filter_phase_from_group_delay(([0.0, 100e6], [tau0, tau0]))
    # transmit IR measured behind the filter: delayed by τ0; receive IR deconvolved by the
    # filtered pressure: advanced by τ0
    tx = pulse(t - 1.0e-6 - tau0)
    rx = pulse(t - 1.0e-6 + tau0)
    r = analyse_phase(tx, FS, rx, FS, filter_phase=filt, duration=None, remove_mean=False)
    np.testing.assert_allclose(r.transmit_compensated, truth, atol=1e-3)
    np.testing.assert_allclose(r.receive_compensated, truth, atol=1e-3)
    assert r.lag_before == pytest.approx(-2 * tau0, abs=1 / FS)
    assert r.lag_after == pytest.approx(0.0, abs=1 / FS)
    assert r.similarity_after > 0.999


def test_packaged_blp15_filter_delays_about_50_ns_at_low_frequency():
    phase = default_filter_phase()
    f = np.array([1e6, 2e6])
    tau = np.diff(phase(f)) / (2 * np.pi * np.diff(f))  # holoprobe: +2π f τ
    assert 45e-9 < tau[0] < 52e-9


def test_phase_command_runs_on_a_small_virtual_transducer(tmp_path):
    t = np.arange(500) / FS
    vt = VirtualTransducer(element_count=4, pitch=0.3e-3, element_width=0.25e-3,
                           element_height=5e-3, transmit_impulse_response=pulse(t - 0.8e-6),
                           transmit_sampling_rate=FS,
                           receive_impulse_response=pulse(t[:200] - 0.3e-6, fc=2.6e6),
                           receive_sampling_rate=100e6)
    vt.save(tmp_path / "virtual_transducer.h5")
    (tmp_path / "summary.json").write_text(json.dumps({"lens_focus": 0.1}))
    res = CliRunner().invoke(app, ["phase", str(tmp_path)])
    assert res.exit_code == 0, res.output
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["lens_focus"] == 0.1
    assert 0 < summary["phase"]["similarity_before"] <= 1
    assert summary["phase"]["filter"].startswith("BLP-15+")
    html = (tmp_path / "report_phase.html").read_text()
    assert "paper Fig. 10" in html and html.count("data:image/png;base64") == 4


def test_every_axis_of_the_phase_figures_has_a_label_with_a_unit():
    t = np.arange(500) / FS
    r = analyse_phase(pulse(t - 0.8e-6), FS, pulse(t - 0.7e-6, fc=2.6e6), FS,
                      filter_phase=default_filter_phase(), duration=None)
    figs = phase_figures(r)
    assert len(figs) == 4
    for fig, caption in figs:
        labels = [lab for ax in fig.axes for lab in (ax.get_xlabel(), ax.get_ylabel())]
        assert len(labels) >= 2
        for label in labels:
            assert re.fullmatch(r"\S.*\([^()]*\S[^()]*\)", label.strip()), label
        assert "Fig. 10" in caption or "chain" in caption


def test_phase_command_writes_its_own_page_when_report_html_cannot_take_a_section(tmp_path):
    t = np.arange(500) / FS
    VirtualTransducer(element_count=4, pitch=0.3e-3, element_width=0.25e-3,
                      element_height=5e-3, transmit_impulse_response=pulse(t - 0.8e-6),
                      transmit_sampling_rate=FS,
                      receive_impulse_response=pulse(t - 0.7e-6),
                      receive_sampling_rate=FS).save(tmp_path / "virtual_transducer.h5")
    old = "<html><body><h1>report of an older holoprobe</h1></body></html>"
    (tmp_path / "report.html").write_text(old)
    res = CliRunner().invoke(app, ["phase", str(tmp_path)])
    assert res.exit_code == 0, res.output
    assert "note: report.html cannot take the section" in res.output
    assert (tmp_path / "report.html").read_text() == old
    assert "paper Fig. 10" in (tmp_path / "report_phase.html").read_text()
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["phase"]["report"] == "report_phase.html"
