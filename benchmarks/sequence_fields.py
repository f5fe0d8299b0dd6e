"""Benchmark: fields of a transmit sequence, per transmit vs one shared element response.

P4-1 preset, 8 focused lines (focus 30 mm, x from −5 to 5 mm, 2-cycle 2.5 MHz burst), an
xz plane x ±10 mm (on the element lattice), z 5–40 mm at 0.5 mm, float32, 36 MHz:
:func:`holoprobe.transducer.predict_field` once per transmit against
:func:`holoprobe.transducer.predict_fields` (the element response computed once; a
common record length, so the records differ only in length, not in their pulses).
Prints wall and CPU time with the load average, and the largest difference of the
per-point pulse energy between the two.

    .venv/bin/python benchmarks/sequence_fields.py [--lines 8]
"""

from __future__ import annotations

import argparse
import math
import os
import time

import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--lines", type=int, default=8)
    args = parser.parse_args()
    from holoprobe.transducer import (
        TransmitSetting,
        VirtualTransducer,
        burst,
        predict_field,
        predict_fields,
    )

    vt = VirtualTransducer.from_preset("p4-1")
    drive = burst(2.5e6, 2, 30.0)
    settings = [TransmitSetting.focused((x, 0.0, 0.03), drive=drive)
                for x in np.linspace(-5e-3, 5e-3, args.lines)]
    xc, yc = vt.aperture_center
    x0 = vt.element_centers()[0, 0]
    hx = vt.pitch / math.ceil(vt.pitch / 0.5e-3 - 1e-9)
    x = x0 + np.arange(math.ceil((xc - 10e-3 - x0) / hx),
                       math.floor((xc + 10e-3 - x0) / hx) + 1) * hx
    gx, gz = np.meshgrid(x, np.arange(5e-3, 40e-3 + 1e-9, 0.5e-3), indexing="ij")
    pts = np.stack([gx.ravel(), np.full(gx.size, yc), gz.ravel()], -1)
    fs = 36e6
    print(f"{len(settings)} transmits × {pts.shape[0]} points, load {os.getloadavg()[0]:.1f}")
    c, t = time.process_time(), time.perf_counter()
    one = [predict_field(vt, s, pts, sampling_rate=fs, time_window="local",
                         dtype=np.float32).pressure for s in settings]
    print(f"predict_field per transmit: wall {time.perf_counter() - t:.1f} s, "
          f"CPU {time.process_time() - c:.1f} s")
    c, t = time.process_time(), time.perf_counter()
    many = [f.pressure for f in predict_fields(vt, settings, pts, sampling_rate=fs)]
    print(f"predict_fields (shared):    wall {time.perf_counter() - t:.1f} s, "
          f"CPU {time.process_time() - c:.1f} s")
    diff = max(np.max(np.abs(np.sum(a.astype(float) ** 2, 1) - np.sum(b.astype(float) ** 2, 1)))
               / np.max(np.sum(a.astype(float) ** 2, 1)) for a, b in zip(one, many, strict=True))
    print(f"largest difference of the per-point pulse energy: {diff:.1e} (relative)")


if __name__ == "__main__":
    main()
