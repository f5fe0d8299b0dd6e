"""Exports of a virtual transducer to simulators: PROTEUS (.mat), k-wave-python, and the
probe descriptions of UFF v0.3, Verasonics (``Trans``) and PyMUST (``param``).

Each part lives in a private module and is re-exported here. k-wave-python is an
optional extra (``pip install holoprobe[kwave]``); it is imported lazily inside the
functions that need it.
"""

from holoprobe.export._kwave import (
    KWAVE_TIME_OFFSET,
    KwavePlaneField,
    kwave_element_pressure,
    kwave_element_strips,
    kwave_grid_mask,
    kwave_grid_source,
    kwave_plane_field,
    kwave_sensor,
    kwave_source,
    kwave_source_signals,
    prepare_kwave_offline,
)
from holoprobe.export._kwave_surface import (
    kwave_surface_ksource,
    kwave_surface_source,
    scan_to_kwave,
)
from holoprobe.export._probes import (
    UFF_VERSION,
    VERASONICS_IR_SAMPLING_RATE,
    export_uff,
    export_verasonics,
    pulse_echo_response,
    pymust_param,
    to_pymust,
    uff_probe_dict,
    verasonics_trans,
)
from holoprobe.export._proteus import (
    PROTEUS_IR_SAMPLING_RATE,
    PROTEUS_TRANSDUCER_FIELDS,
    export_proteus,
    from_proteus_axes,
    import_proteus,
    proteus_transducer_struct,
    to_proteus_axes,
)

__all__ = [
    "KWAVE_TIME_OFFSET",
    "PROTEUS_IR_SAMPLING_RATE",
    "PROTEUS_TRANSDUCER_FIELDS",
    "UFF_VERSION",
    "VERASONICS_IR_SAMPLING_RATE",
    "KwavePlaneField",
    "export_proteus",
    "export_uff",
    "export_verasonics",
    "from_proteus_axes",
    "import_proteus",
    "kwave_element_pressure",
    "kwave_element_strips",
    "kwave_grid_mask",
    "kwave_grid_source",
    "kwave_plane_field",
    "kwave_sensor",
    "kwave_source",
    "kwave_source_signals",
    "kwave_surface_ksource",
    "kwave_surface_source",
    "prepare_kwave_offline",
    "proteus_transducer_struct",
    "pulse_echo_response",
    "pymust_param",
    "scan_to_kwave",
    "to_proteus_axes",
    "to_pymust",
    "uff_probe_dict",
    "verasonics_trans",
]
