"""Reading and writing measurements, results and packaged data.

* Native HDF5 files (schema in ``docs/formats.md``): :func:`write_scan`,
  :func:`read_scan`, :func:`write_echo`, :func:`read_echo`.
* The published MATLAB toolkit's layout (ScanData.mat, TransmitData.mat,
  ReceiveData.mat, sensitivity.mat; v5 and v7.3): :func:`read_reference_scan`,
  :func:`read_reference_echo`, :func:`write_reference_scan`,
  :func:`write_reference_echo`.
* Holograms (CW and transient) of any source: the holography community's MATLAB
  layout (:func:`read_hologram_mat`, :func:`write_hologram_mat`) and the native
  HDF5 one (:func:`read_hologram`, :func:`write_hologram`).
* Any of them: :func:`read_scan_any`, :func:`read_echo_any`, :func:`read_hologram_any`;
  :func:`measurement_kind` tells what a file holds.
* Hydrophone files (complex calibrations CSV/HDF5, waveforms, pressure CSV, JSON):
  :func:`read_complex_calibration`, :func:`write_calibration_h5`,
  :func:`read_waveform_csv`, :func:`write_pressure_csv`, :func:`write_json`.
* Reconstructed sources (surface, normals, areas, complex normal velocity per frequency):
  :func:`write_source`, :func:`read_source` (:class:`SourceVelocity`).
* Safe outputs and provenance: :func:`atomic_write`, :func:`file_sha256`,
  :func:`warm_sha256` (digests computed ahead, e.g. on a thread); JSON: :func:`write_json`,
  :func:`read_json`.
* Sparse matrix probes' element grids (CSV ``ix,iy``): :func:`read_element_grid`.
* Drive files: :func:`read_drive`; source_velocity.h5: :func:`write_source_velocity`,
  :func:`read_source_velocity`.
* Transmit sequences (imaging modes, TOML): :func:`read_transmit_sequence`.
* Chunked field stores (Zarr, xarray-readable, written chunk by chunk, local or
  dask.distributed): :func:`write_field_zarr`, :func:`read_field_zarr`.
* Packaged data: :func:`load_packaged_impulse_responses`,
  :func:`load_probe_preset`, :func:`probe_info_from_preset`.
"""

from holoprobe.io._atomic import atomic_write, file_sha256, warm_sha256
from holoprobe.io._dispatch import (
    NATIVE_FILES,
    NATIVE_SUFFIXES,
    measurement_kind,
    read_echo_any,
    read_hologram_any,
    read_scan_any,
)
from holoprobe.io._drive import read_drive
from holoprobe.io._element_grid import read_element_grid
from holoprobe.io._hdf5 import HDF5Reader
from holoprobe.io._hologram_mat import HOLOGRAM_STRUCTS, read_hologram_mat, write_hologram_mat
from holoprobe.io._hologram_native import (
    KIND_CW_HOLOGRAM,
    KIND_TRANSIENT_HOLOGRAM,
    read_hologram,
    write_hologram,
)
from holoprobe.io._hydrophone import (
    CALIBRATION_FORMAT,
    COMPLEX_CALIBRATION_COLUMNS,
    is_complex_calibration,
    read_complex_calibration,
    read_csv_columns,
    read_waveform_csv,
    write_calibration_h5,
    write_pressure_csv,
)
from holoprobe.io._json import json_default, read_json, write_json
from holoprobe.io._matfile import load_mat, mat_variable_names, save_mat
from holoprobe.io._native import (
    SCHEMA_VERSION,
    probe_array_kind,
    read_echo,
    read_file_kind,
    read_scan,
    write_array_geometry,
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
from holoprobe.io._plausible import check_measurement
from holoprobe.io._reference_mat import (
    REFERENCE_FILES,
    VERASONICS_SOUND_SPEED,
    read_reference_calibration,
    read_reference_echo,
    read_reference_scan,
    write_reference_echo,
    write_reference_scan,
)
from holoprobe.io._results import (
    FIELD_FORMAT,
    FOCAL_VOLUME_FORMAT,
    KWAVE_SOURCE_FORMAT,
    RF_FORMAT,
    FieldWriter,
    field_writer,
    read_results_h5,
    read_source_velocity,
    write_field,
    write_focal_volume,
    write_kwave_source,
    write_rf,
    write_source_velocity,
)
from holoprobe.io._sequence import SEQUENCE_FORMAT, check_toml_format, read_transmit_sequence
from holoprobe.io._source_file import (
    KIND_SOURCE_VELOCITY,
    SourceVelocity,
    read_source,
    write_source,
)
from holoprobe.io._zarr import (
    FIELD_ZARR_KIND,
    read_field_zarr,
    scheduler_address,
    write_field_zarr,
)

__all__ = [
    "CALIBRATION_FORMAT",
    "COMPLEX_CALIBRATION_COLUMNS",
    "FIELD_FORMAT",
    "FIELD_ZARR_KIND",
    "FOCAL_VOLUME_FORMAT",
    "HOLOGRAM_STRUCTS",
    "KIND_CW_HOLOGRAM",
    "KIND_SOURCE_VELOCITY",
    "KIND_TRANSIENT_HOLOGRAM",
    "KWAVE_SOURCE_FORMAT",
    "NATIVE_FILES",
    "NATIVE_SUFFIXES",
    "REFERENCE_FILES",
    "RF_FORMAT",
    "SCHEMA_VERSION",
    "SEQUENCE_FORMAT",
    "VERASONICS_SOUND_SPEED",
    "FieldWriter",
    "HDF5Reader",
    "ImpulseResponses",
    "SourceVelocity",
    "atomic_write",
    "check_measurement",
    "check_toml_format",
    "field_writer",
    "file_sha256",
    "impulse_responses_from_proteus",
    "is_complex_calibration",
    "json_default",
    "load_mat",
    "load_packaged_impulse_responses",
    "load_probe_preset",
    "mat_variable_names",
    "measurement_kind",
    "packaged_data_path",
    "probe_array_kind",
    "probe_info_from_preset",
    "read_complex_calibration",
    "read_csv_columns",
    "read_drive",
    "read_echo",
    "read_echo_any",
    "read_element_grid",
    "read_field_zarr",
    "read_file_kind",
    "read_hologram",
    "read_hologram_any",
    "read_hologram_mat",
    "read_impulse_responses",
    "read_json",
    "read_reference_calibration",
    "read_reference_echo",
    "read_reference_scan",
    "read_results_h5",
    "read_scan",
    "read_scan_any",
    "read_source",
    "read_source_velocity",
    "read_transmit_sequence",
    "read_waveform_csv",
    "save_mat",
    "scheduler_address",
    "warm_sha256",
    "write_array_geometry",
    "write_calibration_h5",
    "write_echo",
    "write_field",
    "write_field_zarr",
    "write_focal_volume",
    "write_hologram",
    "write_hologram_mat",
    "write_impulse_responses",
    "write_json",
    "write_kwave_source",
    "write_pressure_csv",
    "write_reference_echo",
    "write_reference_scan",
    "write_rf",
    "write_scan",
    "write_source",
    "write_source_velocity",
]
