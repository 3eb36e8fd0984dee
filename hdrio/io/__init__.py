"""Reading brackets and their exposures; writing images atomically."""

from hdrio.io.brackets import read_brackets, read_codes
from hdrio.io.exposure import exposure_from_filename, parse_exposure, read_exposure_table
from hdrio.io.write import write_exr, write_preview

__all__ = [
    "exposure_from_filename",
    "parse_exposure",
    "read_brackets",
    "read_codes",
    "read_exposure_table",
    "write_exr",
    "write_preview",
]
