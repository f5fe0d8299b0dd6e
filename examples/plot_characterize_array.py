"""
Characterize a linear array
===========================

A reduced digital twin of a P4-1 phased array (16 of its 96 elements) is scanned by a
simulated hydrophone on a plane 3.5 mm in front of the lens, slightly tilted, with a
peak SNR of 40 dB. :func:`holoprobe.workflow.characterize` finds the plane's pose,
back-projects the field onto the probe face, fits the aperture and the lens, and
deconvolves the transmit impulse response. The estimates are compared with the
twin's truth, which the estimator never sees.
"""

# %%
# Simulate the measurement
# ------------------------
# :func:`holoprobe.simulate.simulate_scan` returns a
# :class:`holoprobe.measurement.HydrophoneScan` (what a reader returns for a real
# file) and the truth it was made from.
from holoprobe.geometry import Pose
from holoprobe.simulate import ArrayModel, simulate_scan
from holoprobe.workflow import characterize

model = ArrayModel.from_preset("p4-1", element_count=16)
pose = Pose.from_degrees(0.5, -0.8, 0.6, (0.1e-3, -0.05e-3, 3.5e-3))
scan, truth = simulate_scan(model, pose=pose, size=(9.6e-3, 19.2e-3), n_samples=192,
                            snr_db=40.0, seed=1)

# %%
# Characterize it
# ---------------
# The run holds the transmit result, the ``summary.json`` tree and the virtual
# transducer; in Jupyter, ``run`` alone shows them as a table.
run = characterize(scan)
summary = run.summary
unc = summary["uncertainty"]
for name, true in [("theta_x_deg", pose.angles_deg[0]), ("theta_y_deg", pose.angles_deg[1])]:
    print(f"scan_plane.{name:12s} {summary['scan_plane'][name]: .5g} "
          f"± {unc['scan_plane'][name]:.2g}   (truth {true: .5g})")
print(f"lens focus     {summary['lens_focus'] * 1e3:.2f} ± {unc['lens_focus'] * 1e3:.2f} mm "
      f"(truth {model.lens_focus * 1e3:.2f} mm)")
print(f"aperture height {summary['aperture']['height'] * 1e3:.3f} "
      f"± {unc['aperture']['height'] * 1e3:.3f} mm (truth {model.element_height * 1e3:.3f} mm)")
print("warnings:", summary["warnings"] or "none")

# %%
# The report's figures
# --------------------
# :meth:`~holoprobe.workflow.CharacterizationRun.figures` returns the figures of
# ``report.html`` as matplotlib figures, section by section; here the reconstructed
# source (paper Fig. 5) with the fitted aperture.
print([title for title, _ in run.figures()])
source_figure = run.figures()[0][1][1]
