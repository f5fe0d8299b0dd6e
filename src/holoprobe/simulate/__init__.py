"""The digital twin: synthetic hydrophone scans and reflector echoes with known truth.

Each piece lives in a private module and is re-exported here. See ``docs/simulator.md``
for what is simulated, the SNR definition and how the synthesis differs from the
characterization pipeline (no inverse crime).
"""

from holoprobe.simulate._array import (
    ArrayModel,
    EdgeMode,
    SourceSampling,
    gaussian_impulse_response,
    rectangular_pulse,
)
from holoprobe.simulate._echo import (
    mirror_points,
    plate_plane,
    simulate_echo,
    virtual_sensor_pose,
)
from holoprobe.simulate._field_truth import simulate_field
from holoprobe.simulate._hologram import (
    VelocityMap,
    acoustic_power_far_field,
    simulate_hologram,
    source_pose,
    tone_burst,
)
from holoprobe.simulate._noise import add_noise, noise_std_for_snr, peak_snr_db, quantize
from holoprobe.simulate._output import write_simulation
from holoprobe.simulate._scan import DEFAULT_SCAN_POSE, simulate_scan, synthesize_pressure
from holoprobe.simulate._spectra import (
    SourceGroup,
    radiate,
    signal_band,
    source_groups,
    source_spectra,
)
from holoprobe.simulate._truth import SimulationTruth, read_truth

__all__ = [
    "DEFAULT_SCAN_POSE",
    "ArrayModel",
    "EdgeMode",
    "SimulationTruth",
    "SourceGroup",
    "SourceSampling",
    "VelocityMap",
    "acoustic_power_far_field",
    "add_noise",
    "gaussian_impulse_response",
    "mirror_points",
    "noise_std_for_snr",
    "peak_snr_db",
    "plate_plane",
    "quantize",
    "radiate",
    "read_truth",
    "rectangular_pulse",
    "signal_band",
    "simulate_echo",
    "simulate_field",
    "simulate_hologram",
    "simulate_scan",
    "source_groups",
    "source_pose",
    "source_spectra",
    "synthesize_pressure",
    "tone_burst",
    "virtual_sensor_pose",
    "write_simulation",
]
