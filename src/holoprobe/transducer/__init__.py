"""The virtual transducer at work: the model, its file, transmit settings, field prediction.

Each part lives in a private module and is re-exported here.
"""

from holoprobe.transducer._model import (
    RECEIVE_UNITS,
    TRANSMIT_UNITS,
    Provenance,
    VirtualTransducer,
)
from holoprobe.transducer._schema import (
    SCHEMA_VERSION,
    read_virtual_transducer,
    write_virtual_transducer,
)

__all__ = [
    "RECEIVE_UNITS",
    "SCHEMA_VERSION",
    "TRANSMIT_UNITS",
    "Provenance",
    "VirtualTransducer",
    "read_virtual_transducer",
    "write_virtual_transducer",
]
