"""Pictures of a merge: response curves, which bracket each pixel came from, luminance in
stops, and a contact sheet of the brackets. PNG files through matplotlib (the ``plot``
extra), imported only when a picture is asked for.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hdrio.errors import HdrioError
from hdrio.io.write import write_image
from hdrio.radiometry.luminance import DEFAULT_SPACE, luminance
from hdrio.radiometry.weighting import weights_table

_CHANNEL_COLOURS = ("tab:red", "tab:green", "tab:blue")


def _pyplot():
    try:
        import matplotlib
    except ImportError:
        raise HdrioError("pictures need matplotlib: pip install 'hdrio[plot]'") from None
    matplotlib.use("Agg")  # files only, never a window
    import matplotlib.pyplot as plt

    return plt


def _save(figure, path: str | Path) -> Path:
    """Render ``figure`` and write it with :func:`hdrio.io.write.write_image` (atomic)."""
    try:
        figure.set_dpi(110)
        figure.canvas.draw()
        rgba = np.asarray(figure.canvas.buffer_rgba())
    finally:
        _pyplot().close(figure)
    return write_image(path, np.ascontiguousarray(rgba[..., :3]), "uint8")


def _seconds(t: float) -> str:
    return f"1/{1 / t:.4g} s" if t < 1 else f"{t:.4g} s"


def plot_response(result, path: str | Path) -> Path:
    """The recovered ``g(z) = ln f^-1(z)`` per channel, with the solve's samples.

    Samples are drawn as in Debevec & Malik's figure 2: code ``Z_ij`` against
    ``ln E_i + ln dt_j``, with ``E_i`` the merged radiance at sample pixel ``i``.
    """
    plt = _pyplot()
    response, stack = result.response, result.stack
    figure, axes = plt.subplots(figsize=(6.4, 4.4), layout="constrained")
    codes = np.arange(response.code_max + 1)
    colours = _CHANNEL_COLOURS if response.channels == 3 else ("0.2",)  # grey: dark grey
    indices = response.parameters.get("sample_indices")
    if indices is not None and len(indices):
        flat = result.radiance.reshape(-1, result.radiance.shape[-1])[indices]
        samples = stack.codes.reshape(stack.count, -1, stack.shape[-1])[:, indices]
        for c in range(response.channels):
            x = np.log(flat[None, :, c]) + stack.log_exposures[:, None]
            axes.scatter(x.reshape(-1), samples[:, :, c].reshape(-1), s=2, alpha=0.15,
                         color=colours[c % len(colours)], linewidths=0)
    for c in range(response.channels):
        axes.plot(response.log_inverse[:, c], codes, color=colours[c % len(colours)],
                  label="RGB"[c] if response.channels == 3 else "Y")
    axes.set_xlabel("log exposure ln(E dt)  (g(z_mid) = 0)")
    axes.set_ylabel("code value z")
    axes.set_title(f"camera response ({response.method})")
    axes.legend(loc="lower right")
    axes.grid(alpha=0.3)
    return _save(figure, path)


def dominant_bracket(result) -> np.ndarray:
    """``(H, W)``: index of the bracket with the largest merge weight at each pixel.

    The merge's policy: per-channel weights ``w(Z)`` on the codes the response supports,
    summed over channels; a pixel saturated in bracket ``j`` is dropped from ``j`` and
    every longer exposure. ``-1`` where no bracket has weight (clipped or black
    everywhere).
    """
    stack, response = result.stack, result.response
    weights = weights_table(result.options.weighting, stack.code_max)[:, None] * response.supported
    channels = np.arange(stack.shape[-1])
    best = np.full(stack.shape[:2], -1, dtype=np.int16)
    best_weight = np.zeros(stack.shape[:2])
    dropped = np.zeros(stack.shape[:2], dtype=bool)
    for j in range(stack.count):
        codes = stack.codes[j]
        dropped |= np.any(codes == stack.code_max, axis=-1)
        weight = np.where(dropped, 0.0, weights[codes, channels].sum(axis=-1))
        better = weight > best_weight
        best[better], best_weight[better] = j, weight[better]
    return best


def plot_contribution(result, path: str | Path) -> Path:
    """A map of :func:`dominant_bracket`, one colour per exposure, with a legend."""
    plt = _pyplot()
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    best = dominant_bracket(result)
    count = result.stack.count
    colours = plt.get_cmap("viridis")(np.linspace(0, 1, count))
    palette = ListedColormap(np.vstack([[0.5, 0.5, 0.5, 1.0], colours]))
    figure, axes = plt.subplots(figsize=(7.2, 4.8), layout="constrained")
    axes.imshow(best + 1, cmap=palette, vmin=0, vmax=count, interpolation="nearest")
    axes.set_axis_off()
    axes.set_title("bracket contributing most to each pixel")
    handles = [Patch(color=colours[j], label=_seconds(t))
               for j, t in enumerate(result.stack.exposures)]
    if np.any(best < 0):
        handles.append(Patch(color=(0.5, 0.5, 0.5), label="none (clipped/black)"))
    figure.legend(handles=handles, loc="outside right center", title="exposure")
    return _save(figure, path)


def plot_stops(radiance: np.ndarray, path: str | Path, space: str = DEFAULT_SPACE,
               reference: float | None = None) -> Path:
    """False-colour luminance in stops from ``reference`` (default: the median), with a
    colour bar. Units: ``log2(L / reference)`` for scene-linear ``L``."""
    plt = _pyplot()
    rgb = np.asarray(radiance, dtype=np.float32)
    L = luminance(rgb[..., :3], space) if rgb.shape[-1] >= 3 else rgb[..., 0]
    positive = L[L > 0]
    if positive.size == 0:
        raise HdrioError(f"{path}: the image has no positive luminance to plot")
    reference = float(np.median(positive)) if reference is None else reference
    stops = np.log2(np.maximum(L, positive.min()) / reference)
    low, high = np.floor(np.percentile(stops, 0.1)), np.ceil(np.percentile(stops, 99.9))
    figure, axes = plt.subplots(figsize=(7.2, 4.8), layout="constrained")
    shown = axes.imshow(stops, cmap="turbo", vmin=low, vmax=high, interpolation="nearest")
    axes.set_axis_off()
    axes.set_title(f"luminance, stops from the median ({reference:.3g})")
    bar = figure.colorbar(shown, ax=axes, fraction=0.046, pad=0.04)
    bar.set_label("stops")
    return _save(figure, path)


def contact_sheet(stack, path: str | Path, columns: int = 4) -> Path:
    """The brackets of ``stack`` side by side, each labelled with its exposure."""
    plt = _pyplot()
    from hdrio.io.raw import is_raw_stack

    rows = -(-stack.count // columns)
    columns = min(columns, stack.count)
    height, width, _ = stack.shape
    scale = 2.6 / max(height, width)
    figure, grid = plt.subplots(rows, columns, squeeze=False, layout="constrained",
                                figsize=(columns * width * scale + 0.4,
                                         rows * (height * scale + 0.45)))
    for j, axes in enumerate(grid.reshape(-1)):
        axes.set_axis_off()
        if j >= stack.count:
            continue
        frame = stack.codes[j].astype(np.float32) / stack.code_max
        if is_raw_stack(stack):  # linear XYZ codes: a rough display encoding to see them
            frame = np.clip(frame, 0.0, 1.0) ** (1 / 2.2)
        axes.imshow(np.squeeze(frame), cmap="gray" if frame.shape[-1] == 1 else None)
        axes.set_title(f"{Path(stack.files[j]).name}\n{_seconds(stack.exposures[j])}",
                       fontsize=8)
    figure.suptitle(f"{stack.count} brackets", fontsize=10)
    return _save(figure, path)
