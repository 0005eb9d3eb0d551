"""Outputs: particle frame series (VTKHDF or VTU/PVTU, a PVD collection) and grid frame series
(VTU/PVTU/PVD), the energies file and summary, the output size estimate, checkpoints and
plots."""

from fempm.io.writers import (
    FRAME_FORMATS,
    GRID_FIELDS,
    OUTPUT_FILES,
    OUTPUT_LIMIT,
    FrameSeries,
    GridField,
    OutputFolderError,
    OutputSizeError,
    OutputWriteError,
    PointFileSeries,
    RunWriter,
    check_output_size,
    earlier_outputs,
    frame_bytes,
    make_folder,
    write_json,
)

__all__ = [
    "FRAME_FORMATS",
    "FrameSeries",
    "GRID_FIELDS",
    "GridField",
    "OUTPUT_FILES",
    "OUTPUT_LIMIT",
    "OutputFolderError",
    "OutputSizeError",
    "OutputWriteError",
    "PointFileSeries",
    "RunWriter",
    "check_output_size",
    "earlier_outputs",
    "frame_bytes",
    "make_folder",
    "write_json",
]
