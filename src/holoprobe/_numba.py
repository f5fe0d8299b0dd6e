"""Numba set-up shared by every parallel kernel of holoprobe.

numba's default threading layer on Linux is OpenMP, and the OpenMP runtime is
shared with finufft, whose single-threaded plans leave the process-wide thread
count at 1: numba's ``prange`` loops then ran on one core (measured: a
``rayleigh_integral`` call took 7.9 s on the OpenMP layer and 4.0 s on
``workqueue`` with 2 cores). holoprobe therefore selects numba's own
``workqueue`` layer, unless the user chose one with ``NUMBA_THREADING_LAYER``.
Import this module before compiling or running a parallel kernel.
"""

from __future__ import annotations

import os

import numba

if "NUMBA_THREADING_LAYER" not in os.environ:
    numba.config.THREADING_LAYER = "workqueue"  # type: ignore[attr-defined]  # set at run time

__all__: list[str] = []
