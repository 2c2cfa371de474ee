"""Plots of learning results (matplotlib, no display needed)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from aptkt.experiments.aggregate import mean_band

__all__ = ["BAND_LABEL", "learning_curves", "save_figure", "figure", "canvas", "METHOD_COLOURS"]

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
    (1 / number of classes), drawn as a dashed line. The legend says what the bands are.
    """

    # Methods without a colour of their own take one that no method of this plot uses.
    spare = iter(c for c in _SPARE_COLOURS if c not in {METHOD_COLOURS.get(m) for m in curves})
    for method, values in curves.items():
        values = np.asarray(values, dtype=float)
        mean, low, high = mean_band(values)
        colour = METHOD_COLOURS.get(method) or next(spare, None)
        ax.plot(x, mean, label=f"{method} (n={values.shape[0]})", color=colour, lw=2)
        ax.fill_between(x, low, high, color=colour, alpha=0.18, lw=0)
    ax.axhline(chance, color="0.4", ls="--", lw=1, label=f"chance ({chance:.2f})")
    ax.plot([], [], " ", label=BAND_LABEL)  # a legend line that only explains the bands
    ax.set_ylim(0, 1.02)
    from matplotlib.ticker import MaxNLocator  # see _pyplot

    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right", fontsize="small")


def save_figure(fig, path_stem: str | Path, formats: Sequence[str] = ("png", "svg")) -> list[Path]:
    path_stem = Path(path_stem)
    path_stem.parent.mkdir(parents=True, exist_ok=True)
    out = []
    for fmt in formats:
        p = path_stem.with_suffix(f".{fmt}")
        fig.savefig(p, dpi=150, bbox_inches="tight")
        out.append(p)
    _pyplot().close(fig)
    return out


def figure(nrows: int = 1, ncols: int = 1, **kw):
    return _pyplot().subplots(nrows, ncols, **kw)


def canvas(**kw):
    """An empty figure, for layouts that ``subplots`` cannot express (grid specs)."""
    return _pyplot().figure(**kw)
