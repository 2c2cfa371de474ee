"""Plots of learning results (matplotlib, no display needed)."""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from aptkt.errors import ConfigError
from aptkt.experiments.aggregate import mean_band
from aptkt.files import replaced_atomically

__all__ = [
    "BAND_LABEL",
    "DRAW_ORDER",
    "METHOD_COLOURS",
    "METHOD_MARKERS",
    "canvas",
    "curve_styles",
    "figure",
    "learning_curves",
    "save_figure",
]

#: The paper's colours (Fig. 9): baseline red, APTKT blue, APTKT with auxiliary features green.
METHOD_COLOURS = {
    "baseline": "tab:red",
    "APTKT": "tab:blue",
    "APTKT+aux": "tab:green",
    "control": "tab:gray",
    # Fig. 6: the multi-modal kernel and the single modalities (the paper's names).
    "Multi": "tab:purple",
    "STIF": "tab:brown",
    "Texture": "tab:olive",
    "Thermal-C": "tab:orange",
}


def _pyplot():
    # Imported when a plot is made: the non-interactive backend must be chosen before pyplot,
    # and matplotlib is slow to import for everything that does not plot.
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


_SPARE_COLOURS = ("tab:pink", "tab:cyan", "black", "tab:olive", "tab:brown")

#: The order curves are drawn in (methods not named here follow, in the order given).
DRAW_ORDER = ("baseline", "control", "APTKT", "APTKT+aux", "Multi", "STIF", "Texture", "Thermal-C")
#: A method keeps its marker in every plot.
METHOD_MARKERS = {
    "baseline": "o",
    "control": "s",
    "APTKT": "^",
    "APTKT+aux": "v",
    "Multi": "D",
    "STIF": "P",
    "Texture": "X",
    "Thermal-C": "*",
}
_SPARE_MARKERS = ("<", ">", "h", "p", "d", "8")
_LINE_STYLES = ("-", "--", ":", "-.", (0, (5, 1, 1, 1, 1, 1)), (0, (8, 2)))
#: Line widths of the first and of the last curve drawn.
_WIDEST, _THINNEST = 3.2, 1.2


def curve_styles(methods: Iterable[str], n_points: int) -> dict[str, dict[str, Any]]:
    """matplotlib keywords of each method's curve, in the order to draw them.

    Each curve drawn later is thinner and more broken than the ones before, with hollow
    markers: where two methods' curves coincide (APTKT and APTKT with auxiliary features often
    do), the later one runs inside the earlier and both stay visible. Every method has its own
    line style (by drawing position), marker and colour; markers sit on about 8 points, each
    method's shifted by a point where there is room.
    """
    names = list(dict.fromkeys(methods))
    rank = {m: i for i, m in enumerate(DRAW_ORDER)}
    ordered = sorted(names, key=lambda m: rank.get(m, len(rank)))
    taken_colours = {METHOD_COLOURS.get(m) for m in ordered}
    spare_colours = iter(c for c in _SPARE_COLOURS if c not in taken_colours)
    taken_markers = {METHOD_MARKERS.get(m) for m in ordered}
    spare_markers = iter(m for m in _SPARE_MARKERS if m not in taken_markers)
    widths = np.linspace(_WIDEST, _THINNEST, len(ordered)) if len(ordered) > 1 else [2.0]
    every = max(1, n_points // 8)
    styles = {}
    for i, (method, lw) in enumerate(zip(ordered, widths)):
        colour = METHOD_COLOURS.get(method) or next(spare_colours, "0.2")
        styles[method] = {
            "color": colour,
            "ls": _LINE_STYLES[i % len(_LINE_STYLES)],
            "lw": float(lw),
            "marker": METHOD_MARKERS.get(method) or next(spare_markers, "."),
            "markevery": (i % every, every),  # coinciding curves' markers side by side
            "ms": 2 + 1.5 * float(lw),
            "mfc": colour if i == 0 else "none",
        }
    return styles


#: What the bands of every learning-curve plot are (shown in the legend).
BAND_LABEL = "bands: 95 % interval of the mean over runs"


def learning_curves(
    ax,
    curves: Mapping[str, np.ndarray],
    x: np.ndarray,
    *,
    chance: float,
    title: str = "",
    ylabel: str = "accuracy on the test set",
    xlabel: str = "observations collected after the initial round",
) -> None:
    """Mean curve with its 95 % interval over runs as a band, per method, and chance level.

    ``curves[method]`` has shape (runs, len(x)); ``chance`` is the accuracy of guessing
    (1 / number of classes), drawn as a dashed line. Accuracies lie in [0, 1] and so do the
    bands (a t interval over few runs reaches beyond). The legend says what the bands are.
    """
    for method, look in curve_styles(curves, len(x)).items():
        values = np.asarray(curves[method], dtype=float)
        mean, low, high = mean_band(values)
        ax.plot(x, mean, label=f"{method} (n={values.shape[0]})", **look)
        ax.fill_between(
            x, np.clip(low, 0, 1), np.clip(high, 0, 1), color=look["color"], alpha=0.15, lw=0
        )
    ax.axhline(chance, color="0.4", ls="--", lw=1, label=f"chance ({chance:.2f})")
    ax.plot([], [], " ", label=BAND_LABEL)  # a legend line that only explains the bands
    ax.set_ylim(0, 1.03)
    from matplotlib.ticker import MaxNLocator  # see _pyplot

    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right", fontsize="small")


def save_figure(fig, path_stem: str | Path, formats: Sequence[str] = ("png", "svg")) -> list[Path]:
    """``fig`` as ``<path_stem>.<format>`` for each format, each written whole by a rename
    (:func:`aptkt.files.replaced_atomically`: a link there is replaced, never followed)."""
    path_stem = Path(path_stem)
    path_stem.parent.mkdir(parents=True, exist_ok=True)
    out = []
    for fmt in formats:
        p = path_stem.with_suffix(f".{fmt}")
        with replaced_atomically(p, ConfigError) as tmp:
            # The temporary name's suffix says nothing of the format: name it.
            fig.savefig(tmp, format=fmt, dpi=150, bbox_inches="tight")
        out.append(p)
    _pyplot().close(fig)
    return out


def label_shares(ax: Any, shares: np.ndarray, shown: np.ndarray | None = None) -> None:
    """Write each cell's share (0..1) on a confusion heat-map, white on dark cells; only the
    cells where ``shown`` is true (default: all)."""
    for i, j in zip(*np.nonzero(np.ones_like(shares, dtype=bool) if shown is None else shown)):
        ax.text(
            j,
            i,
            f"{shares[i, j]:.2f}",
            ha="center",
            va="center",
            fontsize=7,
            color="white" if shares[i, j] > 0.6 else "black",
        )


def figure(nrows: int = 1, ncols: int = 1, **kw):
    return _pyplot().subplots(nrows, ncols, **kw)


def canvas(**kw):
    """An empty figure, for layouts that ``subplots`` cannot express (grid specs)."""
    return _pyplot().figure(**kw)
