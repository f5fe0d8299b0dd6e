"""
Spurious (Lamb-like) modes
==========================

Some probes radiate a wave that runs along the face from the elevation edges
inward, at a frequency of its own (paper section III D). A small twin array is given
such an edge mode (3.3 MHz, phase speed 3000 m/s), scanned 2 mm in front of its face
and back-projected onto it; :func:`holoprobe.analysis.analyse_modes` finds the
mode's frequency and speed in the surface velocity.
"""

# %%
import numpy as np

from holoprobe.analysis import analyse_modes, modes_figures
from holoprobe.geometry import Medium, PlaneGrid, Pose
from holoprobe.measurement import DriveSignal
from holoprobe.propagation import project
from holoprobe.signal import frequency_axis, to_frequency, to_time
from holoprobe.simulate import ArrayModel, EdgeMode, simulate_scan

fs, fs_ir = 25e6, 250e6
t = np.arange(int(2e-6 * fs_ir)) / fs_ir
ir = np.exp(-0.5 * ((t - 1e-6) / 0.25e-6) ** 2) * np.cos(2 * np.pi * 2.5e6 * (t - 1e-6))
mode = EdgeMode(amplitude=0.3, frequency=3.3e6, cycles=2, phase_speed=3000.0, delay=1.2e-6)
model = ArrayModel(element_count=6, pitch=0.5e-3, element_width=0.45e-3,
                   element_height=6e-3, lens_focus=0.06, transmit_ir=ir, receive_ir=ir,
                   ir_sampling_rate=fs_ir, drive=DriveSignal([1.0], fs_ir), edge_mode=mode)
scan_grid = PlaneGrid.centered(32, 60, 0.15e-3, 0.15e-3, Pose(origin=(0, 0, 2e-3)))
band = (0.3e6, 4.9e6)
scan, _ = simulate_scan(model, grid=scan_grid, sampling_rate=fs, n_samples=256,
                        calibration=None, snr_db=40.0, seed=1, band=band, dtype=np.float64)

# %%
# Back-project the scan onto the face and look for the mode
# ---------------------------------------------------------
n = scan.data.shape[-1]
f = frequency_axis(n, fs)
sel = (f > band[0]) & (f < band[1])
source = PlaneGrid.centered(32, 60, 0.15e-3, 0.15e-3)
velocity_spectrum = project(to_frequency(scan.data)[..., sel] / fs, scan_grid, source, f[sel],
                            Medium(), quantity="normal_velocity", method="angular_spectrum")
full = np.zeros((*scan.data.shape[:2], f.size), complex)
full[..., sel] = velocity_spectrum * fs
result = analyse_modes(to_time(full, n), source, fs)
print(f"mode present: {result.present}, f = {result.frequency / 1e6:.2f} MHz (truth 3.30), "
      f"phase velocity = {result.phase_velocity:.0f} m/s (truth 3000)")
dispersion_figure, caption = modes_figures(result)[0]
print(caption)
