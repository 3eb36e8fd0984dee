"""Read an image header (EXR attributes included) with OpenImageIO."""

from __future__ import annotations

from pathlib import Path

from hdrio.errors import InputError, library_message
from hdrio.io.paths import check_input
from hdrio.io.write import Window


def read_header(path: str | Path) -> dict[str, object]:
    """Attributes of ``path`` by name, plus ``.resolution``, ``.channels`` and ``.format``."""
    import OpenImageIO as oiio

    from hdrio.io.native import quiet_native_stderr

    path = Path(path)
    check_input(path)
    with quiet_native_stderr():  # libpng and friends: their lines become our one line
        image = oiio.ImageInput.open(str(path))
        if image is None:
            raise InputError(path, f"cannot read header ({library_message(oiio.geterror)})")
        try:
            spec = image.spec()
            window = Window.of(spec)
            header: dict[str, object] = {
                ".resolution": f"{spec.width}x{spec.height}" + (
                    "" if window is None else f" {window}"),
                ".channels": ",".join(spec.channelnames),
                ".format": str(spec.format),
            }
            for attribute in spec.extra_attribs:
                try:
                    header[attribute.name] = attribute.value
                except UnicodeDecodeError:  # a corrupt text attribute: not worth failing
                    continue
        except UnicodeDecodeError:
            raise InputError(path, "header holds names that are not text: a damaged file"
                             ) from None
        finally:
            image.close()
    return header


def read_typed_attributes(path: str | Path) -> dict[str, object]:
    """Every attribute of ``path`` as a :class:`~hdrio.io.write.Typed` (its OpenImageIO
    type kept), so that writing it again stores the same type (GPS vectors, rationals)."""
    import OpenImageIO as oiio

    from hdrio.io.write import Typed

    image = oiio.ImageInput.open(str(path))
    if image is None:
        raise InputError(path, f"cannot read header ({oiio.geterror().strip()})")
    try:
        return {attribute.name: Typed(str(attribute.type), attribute.value)
                for attribute in image.spec().extra_attribs}
    finally:
        image.close()


EXR_MAGIC = b"\x76\x2f\x31\x01"
"""The first four bytes of every OpenEXR file."""


def require_exr(path: str | Path) -> None:
    """Raise :class:`InputError` unless ``path`` is a readable file that starts as an
    OpenEXR file does, naming what it is instead (a JPEG, say) when OpenImageIO knows."""
    check_input(path, "an OpenEXR file")
    with open(path, "rb") as file:
        start = file.read(len(EXR_MAGIC))
    if start == EXR_MAGIC:
        return
    kind = _image_format(path)
    what = (f"a {kind.upper()} image, not OpenEXR" if kind
            else "not an OpenEXR file (it does not start as one)")
    raise InputError(path, f"{what}: hdrio check reads OpenEXR files (what hdrio merge "
                           "writes)")


def _image_format(path: str | Path) -> str | None:
    """OpenImageIO's name for the format of ``path`` (``jpeg``), or ``None``."""
    import OpenImageIO as oiio

    from hdrio.io.native import quiet_native_stderr

    with quiet_native_stderr():
        image = oiio.ImageInput.open(str(path))
        if image is None:
            oiio.geterror()  # clear it
            return None
        try:
            return image.format_name()
        finally:
            image.close()
