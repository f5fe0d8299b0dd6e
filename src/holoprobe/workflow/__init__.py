"""What one run produces: the layer that both the CLI and a notebook call.

:func:`characterize` reads (or takes) the inputs, runs the estimation of
:mod:`holoprobe.characterize` and returns a :class:`CharacterizationRun`; its
``.save(dir)`` writes summary.json, virtual_transducer.h5, source_velocity.h5 and
report.html (formats in ``docs/formats.md``).

>>> from holoprobe.workflow import characterize          # doctest: +SKIP
>>> run = characterize("scan.h5", echo="echo.h5")        # doctest: +SKIP
>>> run.summary["lens_focus"], run.save("out/")          # doctest: +SKIP
"""

from holoprobe.workflow._convex_run import (
    CONVEX_OUTPUT_FILES,
    ConvexRun,
    characterize_convex,
    is_convex_scan,
)
from holoprobe.workflow._hologram_outputs import (
    HOLOGRAM_OUTPUT_FILES,
    hologram_report_figures,
    source_velocity,
    write_hologram_outputs,
)
from holoprobe.workflow._hologram_run import HologramRun, characterize_hologram_file
from holoprobe.workflow._outputs import (
    OUTPUT_FILES,
    SOURCE_VELOCITY_FILE,
    SUMMARY_FILE,
    report_figures,
    summary_dict,
    virtual_transducer,
    write_outputs,
)
from holoprobe.workflow._row_column import characterize_row_column
from holoprobe.workflow._run import CharacterizationRun, characterize

__all__ = [
    "CONVEX_OUTPUT_FILES",
    "HOLOGRAM_OUTPUT_FILES",
    "OUTPUT_FILES",
    "SOURCE_VELOCITY_FILE",
    "SUMMARY_FILE",
    "CharacterizationRun",
    "ConvexRun",
    "HologramRun",
    "characterize",
    "characterize_convex",
    "characterize_hologram_file",
    "characterize_row_column",
    "hologram_report_figures",
    "is_convex_scan",
    "report_figures",
    "source_velocity",
    "summary_dict",
    "virtual_transducer",
    "write_hologram_outputs",
    "write_outputs",
]
