"""Read an image header (EXR attributes included) with OpenImageIO."""

from __future__ import annotations

from pathlib import Path

from hdrio.errors import InputError
from hdrio.io.paths import check_input


def read_header(path: str | Path) -> dict[str, object]:
    """Attributes of ``path`` by name, plus ``.resolution``, ``.channels`` and ``.format``."""
    import OpenImageIO as oiio

    path = Path(path)
    check_input(path)
    image = oiio.ImageInput.open(str(path))
    if image is None:
        raise InputError(path, f"cannot read header ({oiio.geterror().strip()})")
    try:
        spec = image.spec()
        header: dict[str, object] = {
            ".resolution": f"{spec.width}x{spec.height}",
            ".channels": ",".join(spec.channelnames),
            ".format": str(spec.format),
        }
        for attribute in spec.extra_attribs:
            header[attribute.name] = attribute.value
    finally:
        image.close()
    return header
