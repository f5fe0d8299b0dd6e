"""The virtual transducer at work: the model, its file, transmit settings, field prediction.

Each part lives in a private module and is re-exported here.
"""

from holoprobe.transducer._dask import field_dataset
from holoprobe.transducer._field import (
    FieldPrediction,
    arrival_offsets,
    drive_spectrum,
    element_field,
    element_offsets,
    element_profile,
    predict_field,
    predict_fields,
    record_length,
    signal_band,
    surface_velocity,
    union_band,
)
from holoprobe.transducer._lattice import (
    ElementPlan,
    column_tables_field,
    element_plan,
    lattice_kernel,
    lattice_step,
    unique_pairs,
)
from holoprobe.transducer._model import (
    RECEIVE_UNITS,
    TRANSMIT_UNITS,
    Provenance,
    VirtualTransducer,
)
from holoprobe.transducer._rf import rf_units, simulate_rf
from holoprobe.transducer._scattered import plane_wave_field, plane_wave_targets
from holoprobe.transducer._schema import (
    SCHEMA_VERSION,
    read_virtual_transducer,
    write_virtual_transducer,
)
from holoprobe.transducer._stream import FieldStream
from holoprobe.transducer._tables import (
    ColumnTable,
    column_table,
    interpolation_weights,
    shared_table,
    table_field,
    table_spectra,
)
from holoprobe.transducer._transmit import (
    Apodization,
    DelayLaw,
    TransmitSequence,
    TransmitSetting,
    apodization_weights,
    burst,
    diverging_delays,
    focused_delays,
    plane_wave_delays,
    rectangular_pulse,
)

__all__ = [
    "RECEIVE_UNITS",
    "SCHEMA_VERSION",
    "TRANSMIT_UNITS",
    "Apodization",
    "ColumnTable",
    "DelayLaw",
    "ElementPlan",
    "FieldPrediction",
    "FieldStream",
    "Provenance",
    "TransmitSequence",
    "TransmitSetting",
    "VirtualTransducer",
    "apodization_weights",
    "arrival_offsets",
    "burst",
    "column_table",
    "column_tables_field",
    "diverging_delays",
    "drive_spectrum",
    "element_field",
    "element_offsets",
    "element_plan",
    "element_profile",
    "field_dataset",
    "focused_delays",
    "interpolation_weights",
    "lattice_kernel",
    "lattice_step",
    "plane_wave_delays",
    "plane_wave_field",
    "plane_wave_targets",
    "predict_field",
    "predict_fields",
    "read_virtual_transducer",
    "record_length",
    "rectangular_pulse",
    "rf_units",
    "shared_table",
    "signal_band",
    "simulate_rf",
    "surface_velocity",
    "table_field",
    "table_spectra",
    "union_band",
    "unique_pairs",
    "write_virtual_transducer",
]
