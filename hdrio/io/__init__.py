"""Reading brackets and their exposures; writing images atomically."""

from hdrio.lazy import lazy_attributes

_EXPORTS = {
    "read_brackets": "hdrio.io.brackets", "read_codes": "hdrio.io.brackets",
    "exposure_from_filename": "hdrio.io.exposure", "parse_exposure": "hdrio.io.exposure",
    "read_exposure_table": "hdrio.io.exposure",
    "write_exr": "hdrio.io.write", "write_preview": "hdrio.io.write",
}
__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_attributes(__name__, _EXPORTS)
