"""Export a recovered camera response as a 1D LUT (SPI1D or CLF) plus an OCIO config.

The LUT maps normalised code values ``Z / code_max`` in [0, 1] to hdrio's single-exposure
linearisation ``f^-1(Z) = exp(g(Z))`` (relative, ``g(z_mid) = 0``), one column per channel,
at as many evenly spaced codes as hdrio solved levels (every code for 8-bit; 1024 codes
for 16-bit, linearly interpolated between them). The config is the project's
(:mod:`hdrio.cms.ocioconfig`) plus a colour space that applies the LUT, then the input
encoding's primaries, so
``oiiotool --colorconfig DIR/config.ocio in.png --colorconvert NAME lin_rec709_scene``
linearises that camera's images as hdrio does.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from hdrio.cms.encoding import DEFAULT_ENCODING, ENCODINGS, Encoding
from hdrio.io.write import OutputError, write_text
from hdrio.radiometry.curve import CameraResponse
from hdrio.radiometry.saved_response import response_from_header


def response_table(response: CameraResponse, levels: int | None = None) -> np.ndarray:
    """``f^-1`` at ``levels`` evenly spaced codes (default: every code), ``(levels, 3)``."""
    levels = levels or response.code_max + 1
    codes = np.rint(np.arange(levels) * (response.code_max / (levels - 1))).astype(int)
    table = np.exp(response.log_inverse[codes])
    return np.repeat(table, 3, axis=1) if table.shape[1] == 1 else table


def recorded_linearisation(path: str | Path, header: Mapping[str, object]
                           ) -> tuple[np.ndarray, Encoding]:
    """The ``(levels, 3)`` linearisation table and input encoding recorded by hdrio merge.

    The response comes from :func:`hdrio.radiometry.saved_response.response_from_header`, read at
    the levels it was stored with. Raises :class:`InputError` naming ``path`` when the
    header has no hdrio response.
    """
    response = response_from_header(dict(header), str(path))
    table = response_table(response, int(response.parameters["levels"]))
    recorded = str(header.get("hdrio:inputEncoding", DEFAULT_ENCODING))
    name = next((n for n in ENCODINGS if recorded.startswith(n)), DEFAULT_ENCODING)
    return table, ENCODINGS[name]


def format_spi1d(table: np.ndarray) -> str:
    """Sony Imageworks ``.spi1d`` text: input 0..1, ``len(table)`` entries, 3 components."""
    rows = "\n".join("  " + " ".join(f"{v:.9g}" for v in row) for row in table)
    return (f"Version 1\nFrom 0.0 1.0\nLength {len(table)}\nComponents 3\n{{\n{rows}\n}}\n")


def format_clf(table: np.ndarray, name: str, description: str) -> str:
    """Academy/ASC Common LUT Format (CLF 3) with one 32-bit float ``LUT1D``."""
    rows = "\n".join("      " + " ".join(f"{v:.9g}" for v in row) for row in table)
    return (
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        f'<ProcessList id="hdrio-{name}" compCLFversion="3">\n'
        f"  <Description>{description}</Description>\n"
        '  <LUT1D id="response" inBitDepth="32f" outBitDepth="32f" '
        'interpolation="linear">\n'
        f'    <Array dim="{len(table)} 3">\n{rows}\n    </Array>\n'
        "  </LUT1D>\n</ProcessList>\n")


def export_response(exr: str | Path, output_dir: str | Path, name: str = "camera",
                    lut_format: str = "spi1d") -> list[Path]:
    """Write ``NAME.spi1d`` (or ``.clf``) and ``config.ocio`` into ``output_dir``.

    Returns the paths written. The EXR is only read.
    """
    from hdrio.cms.ocioconfig import add_lut_space, project_config
    from hdrio.io.header import read_header

    output_dir = Path(output_dir)
    if not output_dir.is_dir():
        raise OutputError(f"{output_dir}: folder does not exist")
    if lut_format not in ("spi1d", "clf"):
        raise ValueError(f"LUT format must be spi1d or clf, not {lut_format!r}")
    table, encoding = recorded_linearisation(exr, read_header(exr))
    description = f"hdrio camera response from {Path(exr).name} ({encoding.name} primaries)"
    lut_path = output_dir / f"{name}.{lut_format}"
    text = (format_spi1d(table) if lut_format == "spi1d"
            else format_clf(table, name, description))
    config = add_lut_space(project_config(), name, lut_path.name, encoding.linear_interop_id,
                           description)
    write_text(lut_path, text)
    config_path = write_text(output_dir / "config.ocio", config.serialize())
    return [lut_path, config_path]
