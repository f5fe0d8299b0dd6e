"""Reading and writing measurements, results and packaged data.

* Native HDF5 files (schema in ``docs/formats.md``): :func:`write_scan`,
  :func:`read_scan`, :func:`write_echo`, :func:`read_echo`.
* The published MATLAB toolkit's layout (ScanData.mat, TransmitData.mat,
  ReceiveData.mat, sensitivity.mat; v5 and v7.3): :func:`read_reference_scan`,
  :func:`read_reference_echo`, :func:`write_reference_scan`,
  :func:`write_reference_echo`.
* Any of them: :func:`read_scan_any`, :func:`read_echo_any`.
* Safe outputs and provenance: :func:`atomic_write`, :func:`file_sha256`.
* Packaged data: :func:`load_packaged_impulse_responses`,
  :func:`load_probe_preset`, :func:`probe_info_from_preset`.
"""

from holoprobe.io._atomic import atomic_write, file_sha256
from holoprobe.io._dispatch import NATIVE_SUFFIXES, read_echo_any, read_scan_any
from holoprobe.io._matfile import load_mat, save_mat
from holoprobe.io._native import (
    SCHEMA_VERSION,
    read_echo,
    read_file_kind,
    read_scan,
    write_echo,
    write_scan,
)
from holoprobe.io._packaged import (
    ImpulseResponses,
    impulse_responses_from_proteus,
    load_packaged_impulse_responses,
    load_probe_preset,
    packaged_data_path,
    probe_info_from_preset,
    read_impulse_responses,
    write_impulse_responses,
)
from holoprobe.io._reference_mat import (
    REFERENCE_FILES,
    VERASONICS_SOUND_SPEED,
    read_reference_calibration,
    read_reference_echo,
    read_reference_scan,
    write_reference_echo,
    write_reference_scan,
)

__all__ = [
    "NATIVE_SUFFIXES",
    "REFERENCE_FILES",
    "SCHEMA_VERSION",
    "VERASONICS_SOUND_SPEED",
    "ImpulseResponses",
    "atomic_write",
    "file_sha256",
    "impulse_responses_from_proteus",
    "load_mat",
    "load_packaged_impulse_responses",
    "load_probe_preset",
    "packaged_data_path",
    "probe_info_from_preset",
    "read_echo",
    "read_echo_any",
    "read_file_kind",
    "read_impulse_responses",
    "read_reference_calibration",
    "read_reference_echo",
    "read_reference_scan",
    "read_scan",
    "read_scan_any",
    "save_mat",
    "write_echo",
    "write_impulse_responses",
    "write_reference_echo",
    "write_reference_scan",
    "write_scan",
]
