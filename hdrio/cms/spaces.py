"""OpenColorIO colour spaces: configs, conversions, display views and EXR chromaticities.

The public core API for every front end (``hdrio merge --colorspace``, an oiiotool-style
``--colorconvert`` / ``--ociodisplay`` chain, the Blender add-on): functions that take and
return numpy arrays plus colour-space names, resolved in one OpenColorIO config.

Config precedence: an explicit path or ``ocio://`` URI, else ``$OCIO``, else OpenColorIO's
built-in ``ocio://cg-config-latest`` (ACES 2 CG config: ``ACEScg``, ``ACES2065-1``,
``Linear Rec.709 (sRGB)``, ...). Names are looked up with OCIO's aliases, so
``lin_ap1_scene``, ``ACEScg`` and ``ACES - ACEScg`` are the same space.

The EXR ``chromaticities`` of a space come from its Color Interop Forum ID where hdrio
knows it (:data:`INTEROP_COLOURSPACES`, values from colour-science); for other scene-linear
spaces they are derived from the config's own matrix to ``aces_interchange``
(ACES2065-1), i.e. as that config sees them under the ACES white.
"""

from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path

import numpy as np

from hdrio.errors import HdrioError
from hdrio.parallel import on_threads, row_bands

BUILTIN_CONFIG = "ocio://cg-config-latest"
DEFAULT_WORKING_SPACE = "lin_rec709_scene"

# Color Interop Forum IDs of scene-linear spaces -> colour-science colourspace names.
INTEROP_COLOURSPACES: dict[str, str] = {
    "lin_rec709_scene": "ITU-R BT.709",
    "lin_ap1_scene": "ACEScg",
    "lin_ap0_scene": "ACES2065-1",
    "lin_p3d65_scene": "Display P3",
    "lin_rec2020_scene": "ITU-R BT.2020",
    "lin_adobergb_scene": "Adobe RGB (1998)",
}

# AP0 (ACES2065-1) primaries and the ACES white, for spaces outside the table above.
_AP0_CHROMATICITIES = (0.7347, 0.2653, 0.0, 1.0, 0.0001, -0.077, 0.32168, 0.33767)


def _ocio():
    import PyOpenColorIO

    return PyOpenColorIO


def config_source(config: str | os.PathLike[str] | None = None) -> str:
    """Which config to use: ``config`` if given, else ``$OCIO``, else the built-in one."""
    if config is not None and str(config):
        return str(config)
    return os.environ.get("OCIO") or BUILTIN_CONFIG


@lru_cache(maxsize=8)
def _load(source: str):
    ocio = _ocio()
    if not source.startswith("ocio://") and not Path(source).is_file():
        raise HdrioError(f"{source}: OCIO config not found")
    try:
        return ocio.Config.CreateFromFile(source)
    except Exception as error:  # OCIO raises its own Exception subclass
        message = str(error).strip().splitlines()[0] if str(error).strip() else "invalid"
        raise HdrioError(f"{source}: cannot load OCIO config ({message})") from None


def load_config(config: str | os.PathLike[str] | None = None):
    """The ``PyOpenColorIO.Config`` for ``config`` (see :func:`config_source`), cached."""
    return _load(config_source(config))


def config_label(config: str | os.PathLike[str] | None = None) -> str:
    """``source (name)`` of the config, as recorded in the EXR (``hdrio:ocioConfig``)."""
    source = config_source(config)
    name = load_config(config).getName()
    return f"{source} ({name})" if name and name != source else source


def colour_space(name: str, config: str | os.PathLike[str] | None = None):
    """The ``PyOpenColorIO.ColorSpace`` called ``name`` (or an alias of it).

    Raises :class:`HdrioError` naming the config and the scene-linear choices.
    """
    loaded = load_config(config)
    space = loaded.getColorSpace(name)
    if space is None:
        raise HdrioError(
            f"{config_source(config)}: no colour space {name!r}; scene-linear ones: "
            f"{', '.join(linear_space_names(config))}"
        )
    return space


def canonical_space(name: str, config: str | os.PathLike[str] | None = None) -> str:
    """The config's own name for ``name`` (aliases resolved)."""
    return colour_space(name, config).getName()


def interop_id(name: str, config: str | os.PathLike[str] | None = None) -> str | None:
    """The space's Color Interop Forum ID (OpenEXR ``colorInteropID``), if the config says.

    OCIO 2.5+ stores it on the space; older configs may list it among the aliases.
    """
    space = colour_space(name, config)
    known = getattr(space, "getInteropID", lambda: "")() or ""
    if known:
        return known
    for alias in (space.getName(), *space.getAliases()):
        if alias in INTEROP_COLOURSPACES:
            return alias
    return None


def _cpu(source: str, target: str, config):
    loaded = load_config(config)
    try:
        return loaded.getProcessor(canonical_space(source, config),
                                   canonical_space(target, config)).getDefaultCPUProcessor()
    except HdrioError:
        raise
    except Exception as error:
        raise HdrioError(f"{config_source(config)}: cannot convert {source!r} to {target!r} "
                         f"({str(error).strip()})") from None


def _apply(processor, rgb: np.ndarray) -> np.ndarray:
    """``processor`` applied to a float32 copy of ``rgb``, band by band of rows
    (:func:`hdrio.parallel.row_bands`) on every thread (OCIO releases the GIL). A 24 MP
    image as one call took 1.3 s and two full-size copies; in bands, 0.4 s on 2 cores,
    the values identical."""
    rgb = np.asarray(rgb)
    if rgb.shape[-1] != 3:
        raise ValueError(f"expected RGB values (..., 3), got shape {rgb.shape}")
    out = np.empty(rgb.shape, np.float32)
    if rgb.ndim < 2:  # one pixel
        out[...] = rgb
        processor.applyRGB(out.reshape(-1, 3))
        return out
    bands = row_bands(rgb)

    def apply(start: int, stop: int) -> None:
        for top in bands[start:stop]:
            rows = out[top:top + bands.step]
            rows[...] = rgb[top:top + bands.step]
            processor.applyRGB(rows.reshape(-1, 3))

    on_threads(apply, len(bands))
    return out


def convert(rgb: np.ndarray, source: str, target: str,
            config: str | os.PathLike[str] | None = None) -> np.ndarray:
    """Convert ``rgb`` (``(..., 3)``) from colour space ``source`` to ``target``.

    Units are kept (relative or cd/m^2 scene-linear stays so); returns a new float32
    array, the input is never modified.
    """
    if canonical_space(source, config) == canonical_space(target, config):
        return np.array(rgb, dtype=np.float32)
    return _apply(_cpu(source, target, config), rgb)


def display_view(rgb: np.ndarray, source: str, display: str, view: str,
                 config: str | os.PathLike[str] | None = None) -> np.ndarray:
    """Render scene-linear ``rgb`` in ``source`` through an OCIO display and view.

    Returns display-encoded values (e.g. sRGB code values / 255 for ``sRGB - Display``),
    ready for an 8-bit file after clipping to [0, 1].
    """
    ocio = _ocio()
    loaded = load_config(config)
    if display not in loaded.getDisplays():
        raise HdrioError(f"{config_source(config)}: no display {display!r}; choose from "
                         f"{', '.join(loaded.getDisplays())}")
    if view not in loaded.getViews(display):
        raise HdrioError(f"{config_source(config)}: display {display!r} has no view {view!r};"
                         f" choose from {', '.join(loaded.getViews(display))}")
    transform = ocio.DisplayViewTransform(src=canonical_space(source, config),
                                          display=display, view=view)
    return _apply(loaded.getProcessor(transform).getDefaultCPUProcessor(), rgb)


def linear_space_names(config: str | os.PathLike[str] | None = None) -> list[str]:
    """Names of the config's scene-referred spaces whose transform is a 3x3 matrix."""
    names = []
    loaded = load_config(config)
    ocio = _ocio()
    for space in loaded.getColorSpaces():
        if (space.getReferenceSpaceType() == ocio.REFERENCE_SPACE_SCENE
                and not space.isData() and _is_linear(space.getName(), config)):
            names.append(space.getName())
    return names


def rgb_to_reference_matrix(name: str, config: str | os.PathLike[str] | None = None
                            ) -> np.ndarray | None:
    """The 3x3 matrix from ``name`` to the config's ``aces_interchange`` space, or ``None``.

    Found by converting the unit primaries; ``None`` when the conversion is not linear
    (an encoding such as ACEScct or sRGB-encoded, or a display space).
    """
    loaded = load_config(config)
    reference = loaded.getRoleColorSpace("aces_interchange") or loaded.getRoleColorSpace(
        "scene_linear")
    if reference is None:
        raise HdrioError(f"{config_source(config)}: no aces_interchange or scene_linear role")
    try:
        processor = _cpu(name, reference, config)
    except HdrioError:
        return None
    probe = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [4, 0, 0], [0, 0.25, 0],
                      [0, 0, 16], [0.5, 2, 8]], dtype=np.float32)
    out = _apply(processor, probe).astype(np.float64)
    matrix = out[:3].T
    predicted = probe.astype(np.float64) @ matrix.T
    if not np.all(np.isfinite(out)) or not np.allclose(out, predicted, rtol=1e-4, atol=1e-6):
        return None
    return matrix


def _is_linear(name: str, config) -> bool:
    try:
        return rgb_to_reference_matrix(name, config) is not None
    except HdrioError:
        return False


def require_scene_linear(name: str, config: str | os.PathLike[str] | None = None) -> str:
    """``name``'s canonical name, or :class:`HdrioError` if EXR pixels cannot be in it."""
    canonical = canonical_space(name, config)
    if rgb_to_reference_matrix(canonical, config) is None:
        raise HdrioError(f"{name!r} is not a scene-linear colour space of "
                         f"{config_source(config)}; an EXR holds linear light (choose from "
                         f"{', '.join(linear_space_names(config))})")
    return canonical


def colour_science_name(name: str, config: str | os.PathLike[str] | None = None) -> str | None:
    """The colour-science ``RGB_COLOURSPACES`` name of ``name``, when hdrio knows it."""
    return INTEROP_COLOURSPACES.get(interop_id(name, config) or "")


def chromaticities(name: str, config: str | os.PathLike[str] | None = None
                   ) -> tuple[float, ...]:
    """OpenEXR ``chromaticities`` of scene-linear space ``name``: R, G, B, white ``x, y``.

    From colour-science for known interop IDs; otherwise derived from the config's matrix
    to ACES2065-1 (primaries and white of the unit RGB vectors under the ACES white).
    """
    from hdrio.radiometry.luminance import rgb_chromaticities

    known = colour_science_name(name, config)
    if known is not None:
        return rgb_chromaticities(known)
    return derived_chromaticities(name, config)


def derived_chromaticities(name: str, config: str | os.PathLike[str] | None = None
                           ) -> tuple[float, ...]:
    """Chromaticities of ``name`` from the config's matrix to ACES2065-1 (see module doc)."""
    from hdrio.radiometry.luminance import normalised_primary_matrix

    matrix = rgb_to_reference_matrix(name, config)
    if matrix is None:
        raise HdrioError(f"{name!r}: not a scene-linear space, it has no chromaticities")
    to_xyz = normalised_primary_matrix(_AP0_CHROMATICITIES) @ matrix
    xyz = np.column_stack([to_xyz, to_xyz.sum(axis=1)]).T  # R, G, B, white
    xy = xyz[:, :2] / xyz.sum(axis=1, keepdims=True)
    return tuple(float(v) for v in xy.reshape(-1))


def display_view_names(display: str, view: str | None = None,
                       config: str | os.PathLike[str] | None = None) -> tuple[str, str]:
    """``(display, view)`` checked against the config (``view`` ``None``: the display's
    default); raises :class:`HdrioError` listing the choices."""
    loaded = load_config(config)
    displays = list(loaded.getDisplays())
    if display not in displays:
        raise HdrioError(f"{config_source(config)}: no display {display!r}; choose from "
                         f"{', '.join(displays)}")
    views = list(loaded.getViews(display))
    view = view or loaded.getDefaultView(display)
    if view not in views:
        raise HdrioError(f"display {display!r} has no view {view!r}; choose from "
                         f"{', '.join(views)}")
    return display, view
