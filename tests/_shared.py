"""Where the project's reference material lives, for the few tests that read it.

The published toolkit's data files (``shared/reference/data`` beside the repository:
the real hydrophone calibration, the PROTEUS settings with the measured P4-1 impulse
responses, the BLP-15+ datasheet) let some tests check holoprobe against the original
files. A user's clone has no ``shared/``: those tests skip cleanly (``skipif`` on
:data:`SHARED_DATA` existing); the package itself only uses its own copies in
``src/holoprobe/data``.
"""

from pathlib import Path

SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "reference" / "data"
