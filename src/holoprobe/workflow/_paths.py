"""The path type that the workflow entry points accept for their input files."""

from __future__ import annotations

import os

__all__ = ["PathLike"]

PathLike = str | os.PathLike
"""A file name: a ``str`` or an :class:`os.PathLike` (e.g. :class:`pathlib.Path`)."""
