"""
Export a virtual transducer and load it back
============================================

A virtual transducer travels to other simulators: PROTEUS (``Transducer.mat`` and
its impulse-response files), UFF v0.3 (the probe of an ultrasound file format
``.uff``, HDF5) and k-wave-python (the source signals of the element strips on
k-Wave's time axis). Each export is read back here with a different reader than the
one that wrote it.
"""

# %%
import tempfile
from pathlib import Path

import h5py
import matplotlib.pyplot as plt
import numpy as np

from holoprobe.export import export_proteus, export_uff, import_proteus, kwave_source_signals
from holoprobe.transducer import TransmitSetting, VirtualTransducer, burst

vt = VirtualTransducer.from_preset("p4-1").replace(element_count=8, aperture_width=None)
out = Path(tempfile.mkdtemp())

# %%
# PROTEUS, and back
# -----------------
files = export_proteus(vt, out / "proteus")
back = import_proteus(out / "proteus", medium=vt.medium)
print(sorted(p.name for p in files.values()))
print(f"pitch {back.pitch * 1e3:.4f} mm (was {vt.pitch * 1e3:.4f}), "
      f"lens focus {back.lens_focus * 1e3:.1f} mm (was {vt.lens_focus * 1e3:.1f})")

# %%
# UFF v0.3 probe, read with h5py
# ------------------------------
path = export_uff(vt, out / "probe.uff")
with h5py.File(path, "r") as f:
    probe = f["uff.probe"]
    x = np.array([probe[f"element/{i:08d}/transform/translation/x"][()]
                  for i in range(1, vt.element_count + 1)])
    ir = probe["element_impulse_response/00000001/data"][()]
print("element x (mm):", np.round(x * 1e3, 3))

# %%
# k-Wave source signals of a 15° plane wave
# -----------------------------------------
from holoprobe.transducer import DelayLaw

setting = TransmitSetting(burst(2.5e6, 2, 30.0),
                          delays=DelayLaw(kind="plane_wave", angle=np.radians(15)))
dt, nt = 20e-9, 300
signals = kwave_source_signals(vt, setting, dt, nt)

fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(9, 3.2), layout="constrained")
t_ir = np.arange(vt.transmit_impulse_response.size) / vt.transmit_sampling_rate
ax0.plot(t_ir * 1e6, vt.transmit_impulse_response, label="holoprobe")
ax0.plot(np.arange(ir.size) / vt.transmit_sampling_rate * 1e6, ir, "--", label="UFF file")
ax0.set(xlabel="t (µs)", ylabel=f"h_T ({vt.transmit_units})", title="transmit IR")
ax0.legend()
ax1.imshow(signals, aspect="auto", cmap="RdBu_r", extent=(0, nt * dt * 1e6, signals.shape[0], 0))
ax1.set(xlabel="t (µs)", ylabel="element strip", title="k-Wave source signals (Pa)")
