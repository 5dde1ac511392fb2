"""The colours of the classes of motion and the class images, legends and marks the map figures share."""

from __future__ import annotations

import numpy as np

__all__ = ["CLASS_COLOURS", "DENSE_CELLS", "OTHER_PERIODIC", "class_palette", "map_dpi"]


#: Fixed colours of the main classes (the paper's Fig. 12: period 1 red, period 1/2 green).
CLASS_COLOURS = {
    "no impact": "#e8e8e8", "1/1": "#d62728", "1/2": "#2ca02c", "2/2": "#ff7f0e", "1/3": "#1f77b4",
    "2/3": "#9467bd", "2/4": "#8c564b", "2/1": "#e377c2", "chaotic/non-periodic": "#000000",
    "integration failed": "#ffff00", "inside the stop": "#ffffff", "unsettled": "#9ecae1",
}
OTHER_PERIODIC = "other periodic"
_OTHER_COLOUR = "#7570b3"


def class_palette(labels) -> dict[str, str]:
    """Colour per class present: the fixed ones (:data:`CLASS_COLOURS`), every other class one colour.

    The other classes share one colour, named once in the legend as 'other periodic (N classes)': a map has up to
    twenty rare classes, and as many shades of grey and brown could not be told apart (the CSV keeps each class).
    """
    present = set(labels)
    palette = {c: CLASS_COLOURS[c] for c in CLASS_COLOURS if c in present}
    for c in sorted(present - set(palette)):
        palette[c] = _OTHER_COLOUR
    return palette


#: Above this many cells along an axis a map is drawn as an image of one pixel block per cell (not a mesh of
#: cells with edges) and coexisting attractors as a shaded overlay (not one marker per cell).
DENSE_CELLS = 120


def _class_image(ax, x, y, labels, palette):
    from matplotlib.colors import ListedColormap

    names = list(palette)
    index = {c: i for i, c in enumerate(names)}
    grid = np.array([[index[c] for c in row] for row in labels])
    cmap = ListedColormap([palette[c] for c in names])
    if max(grid.shape) > DENSE_CELLS and len(x) > 1 and len(y) > 1:
        dx = (x[-1] - x[0]) / (len(x) - 1) / 2
        dy = (y[-1] - y[0]) / (len(y) - 1) / 2
        ax.imshow(grid, cmap=cmap, vmin=-0.5, vmax=len(names) - 0.5, origin="lower", aspect="auto",
                  interpolation="nearest", extent=(x[0] - dx, x[-1] + dx, y[0] - dy, y[-1] + dy))
        return
    ax.pcolormesh(x, y, grid, cmap=cmap, vmin=-0.5, vmax=len(names) - 0.5, shading="nearest")


def _half_widths(v) -> np.ndarray:
    """Half the spacing around each value of a map axis (half the value's size, or 0.5, for a single one)."""
    v = np.asarray(v, dtype=float)
    if v.size < 2:
        return np.full(v.size, 0.5 * abs(float(v[0])) if v.size and v[0] else 0.5)
    d = np.abs(np.diff(v)) / 2
    return np.concatenate(([d[0]], (d[:-1] + d[1:]) / 2, [d[-1]]))


def _mark_invalid_cells(ax, x, y, rules) -> list:
    """Cover the cells outside the model's valid domain with hatched grey; returns the legend's entry.

    ``rules``: each cell's ``invalid_rule`` field (rows along ``y``, columns along ``x``); empty when valid.
    """
    from matplotlib.collections import PolyCollection
    from matplotlib.patches import Patch

    rows, cols = np.nonzero(rules != "")
    if not len(rows):
        return []
    hx, hy = _half_widths(x), _half_widths(y)
    # One box per cell, its corners as whole arrays (no patch object per cell): counter-clockwise from the lower left.
    x0 = np.asarray(x, dtype=float)[cols] - hx[cols]
    y0 = np.asarray(y, dtype=float)[rows] - hy[rows]
    x1, y1 = x0 + 2 * hx[cols], y0 + 2 * hy[rows]
    boxes = np.stack([np.stack([x0, y0], axis=1), np.stack([x1, y0], axis=1), np.stack([x1, y1], axis=1),
                      np.stack([x0, y1], axis=1)], axis=1)
    # Grey at 60 % over the class colour (still guessable beneath), hatched: distinct from every class colour.
    # An (n, 4, 2) array takes matplotlib's fast path (one template path's codes for all); its stubs say a sequence.
    ax.add_collection(PolyCollection(boxes, closed=True, facecolor=(0.6, 0.6, 0.6, 0.6),  # type: ignore[arg-type]
                                     edgecolor=(0.3, 0.3, 0.3, 1.0), hatch="//", lw=0, zorder=3))
    names = sorted({name for r in rules[rows, cols].tolist() for name in r.split(";") if name})
    return [Patch(facecolor=(0.6, 0.6, 0.6, 0.6), edgecolor=(0.3, 0.3, 0.3, 1.0), hatch="//",
                  label="outside the model's valid domain:\n" + ", ".join(names))]


def map_dpi(shape) -> int:
    """Resolution that gives each cell of a map at least about one pixel (120 to 300 dpi).

    ``shape`` is ``(rows, columns)``; the axes of the map figures are about 4.5 in high and 6.5 in wide.
    """
    rows, cols = shape[-2], shape[-1]
    return int(min(300, max(120, 1.1 * max(rows / 4.5, cols / 6.5))))


def _class_legend(ax, palette, extra=()):
    from matplotlib.patches import Patch

    handles, others = [], 0
    for name, col in palette.items():
        if col == _OTHER_COLOUR:
            others += 1
        else:
            handles.append(Patch(facecolor=col, edgecolor="0.5", label=name))
    if others:
        handles.append(Patch(facecolor=_OTHER_COLOUR, edgecolor="0.5", label=f"{OTHER_PERIODIC} ({others} classes)"))
    ax.legend(handles=[*handles, *extra], fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0),
              title="impacts / cycles", title_fontsize=8)
