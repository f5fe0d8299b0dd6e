"""
Predict a focused field and its acoustic output
===============================================

A virtual transducer predicts the pressure of any transmit setting. Here a
16-element cut of the packaged P4-1 model (published geometry, measured impulse
responses) focuses a 2-cycle, 30 V burst at 30 mm
(``aperture_width=None``: the width of the 16 elements, (N − 1)·pitch + w); the
field on the xz plane and the IEC 62127-1 / FDA quantities (p_r, PII, I_sppa, MI)
along the beam axis follow.
"""

# %%
import matplotlib.pyplot as plt
import numpy as np

from holoprobe.exposure import exposure_metrics
from holoprobe.transducer import (
    DelayLaw,
    TransmitSetting,
    VirtualTransducer,
    burst,
    predict_field,
)

vt = VirtualTransducer.from_preset("p4-1").replace(element_count=16, aperture_width=None)
setting = TransmitSetting(burst(2.5e6, 2, 30.0),
                          delays=DelayLaw(kind="focused", point=(0.0, 0.0, 30e-3)))
vt

# %%
# The field on the xz plane
# -------------------------
# Points in transducer coordinates (m; x along the array, z away from the face,
# :doc:`/conventions`); ``predict_field`` returns the pressure waveforms there.
x = np.arange(-6e-3, 6.01e-3, 0.5e-3)
z = np.arange(5e-3, 50.01e-3, 1e-3)
xx, zz = np.meshgrid(x, z, indexing="ij")
points = np.column_stack([xx.ravel(), 0 * xx.ravel(), zz.ravel()])
field = predict_field(vt, setting, points)
p = field.pressure.reshape(x.size, z.size, -1)
peak_negative = -p.min(axis=-1)

fig, ax = plt.subplots(figsize=(7, 3.2), layout="constrained")
im = ax.pcolormesh(z * 1e3, x * 1e3, peak_negative / 1e3, shading="auto", cmap="magma")
ax.set(xlabel="z (mm)", ylabel="x (mm)", title="peak rarefactional pressure, focus 30 mm")
fig.colorbar(im, ax=ax, label="p_r (kPa)")

# %%
# Acoustic output on the axis
# ---------------------------
axis_points = np.column_stack([0 * z, 0 * z, z])
on_axis = predict_field(vt, setting, axis_points)
metrics = exposure_metrics(on_axis.pressure, on_axis.sampling_rate, axis_points, vt.medium,
                           prf=1e3)
print(f"p_r,3 = {metrics.peak_rarefactional_pressure_derated / 1e3:.1f} kPa, "
      f"MI = {metrics.mechanical_index:.3f} at z = {metrics.depth_mi * 1e3:.1f} mm, "
      f"I_sppa = {metrics.isppa / 1e4:.3g} W/cm²")
