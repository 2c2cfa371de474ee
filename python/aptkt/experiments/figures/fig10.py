"""Fig. 10: object similarity from per-action Gaussian mixture models (paper §5.6), and the
priors dissimilar to the new objects that Fig. 11 transfers from.

Per action, every object's pool observations (never the test set) in the feature space the
learner uses — the feature pipeline fitted on those observations — are clustered as described
in :mod:`aptkt.experiments.similarity`. The "all actions" matrix is the mean of the actions'
confusion matrices, rescaled.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from aptkt.errors import ConfigError
from aptkt.experiments.figures.analysis import Analysis, hide_unused, panel_grid
from aptkt.experiments.figures.base import Context, Headline, Plan
from aptkt.experiments.plots import save_figure
from aptkt.experiments.report import PAPER, markdown_table
from aptkt.experiments.similarity import (
    dissimilar_priors,
    fit_mixture,
    log_confusion,
    log_responsibilities,
    rescale,
)
from aptkt.experiments.tables import write_csv
from aptkt.files import write_json_atomically
from aptkt.learning import FeaturePipeline
from aptkt.learning.dataset import load_observations

NAME = "fig10"
TITLE = "object similarity (GMM confusion) and the dissimilar priors"
ALL = "all"
#: Covariance of the mixtures (see aptkt.experiments.similarity for why it is tied).
COVARIANCE = "tied"


def similarity(ctx: Context) -> dict[str, Any]:
    """Per action (and ``"all"``): the rescaled confusion matrix, the chosen dissimilar priors,
    the priors' scores and the EM diagnostics. Computed once per context."""
    if NAME in ctx.cache:
        return ctx.cache[NAME]
    s = ctx.scale
    objects = list(s.objects)
    table = load_observations(ctx.data, actions=s.actions, objects=objects, trials=s.pool_trials)
    logs, matrices, fits = {}, {}, {}
    for a in s.actions:
        obs = table[a]
        X, _ = FeaturePipeline().fit(obs).transform(obs)
        labels = np.array([objects.index(o) for o in obs.objects])
        fit = fit_mixture(
            X, labels, len(objects), covariance_type=COVARIANCE, max_iter=100, tol=1e-3
        )
        logs[a] = log_confusion(log_responsibilities(fit, X), labels, len(objects))
        matrices[a] = rescale(np.exp(logs[a]))
        fits[a] = {
            "n_iter": fit.n_iter,
            "converged": fit.converged,
            "mean_log_likelihood": fit.lower_bound,
            "observations": int(X.shape[0]),
            "dimensions": int(X.shape[1]),
        }
    # The average over actions of the confusion matrices, in logs: log(mean_a C_a).
    stacked = np.stack([logs[a] for a in s.actions])
    top = stacked.max(axis=0)
    logs[ALL] = top + np.log(np.exp(stacked - top).mean(axis=0))
    matrices[ALL] = rescale(np.exp(logs[ALL]))
    chosen, scores = {}, {}
    for key in matrices:
        chosen[key], scores[key] = dissimilar_priors(
            logs[key], objects, s.priors, s.new_objects, s.dissimilar_count
        )
    result = {
        "objects": objects,
        "matrices": matrices,
        "dissimilar": chosen,
        "scores": scores,
        "em": fits,
    }
    ctx.cache[NAME] = result
    return result


def plan(ctx: Context) -> Plan:
    return Plan()  # no learning runs: the analysis reads the data set


class _Fig10(Analysis):
    name, title = NAME, TITLE

    def measure(self) -> None:
        self.sim = similarity(self.ctx)
        self.objects, self.matrices = self.sim["objects"], self.sim["matrices"]
        self.chosen = self.sim["dissimilar"]
        self.keys = list(self.matrices)

    def draw(self) -> list[str]:
        ctx, objects, out = self.ctx, self.objects, self.ctx.figure_dir(NAME)
        fig, axes = panel_grid(len(self.keys), size=(4.6, 5.2), extra_width=2, layout="constrained")
        ncols = min(4, len(self.keys))
        prior_set = set(ctx.scale.priors)
        names = [ctx.label(o) for o in objects]
        for panel, (ax, key) in enumerate(zip(axes, self.keys)):
            first = panel % ncols == 0  # panels of a row share their rows: one set of row labels
            im = ax.imshow(self.matrices[key], vmin=0, vmax=1, cmap="viridis")
            ax.set_xticks(range(len(objects)), names, fontsize=6, rotation=90)
            ax.set_yticks(range(len(objects)), names if first else [], fontsize=6)
            if first:
                ax.set_ylabel("row: observations of this object", fontsize=8)
            ax.set_xlabel("column: assigned to this object's mixture component", fontsize=8)
            # The paper's colours: old objects' numbers blue, new objects' red.
            for lab, obj in zip(ax.get_xticklabels() + ax.get_yticklabels(), objects + objects):
                lab.set_color("tab:blue" if obj in prior_set else "tab:red")
            ax.set_title(
                f"{key}: dissimilar {ctx.numbers(self.chosen[key])}"
                if key != ALL
                else f"average: dissimilar {ctx.numbers(self.chosen[key])}",
                fontsize=10,
            )
        hide_unused(axes, len(self.keys))
        fig.colorbar(im, ax=axes, shrink=0.6, label="similarity (rescaled confusion)")
        fig.suptitle(
            "Fig. 10 — object confusion from Gaussian mixture models (blue: prior, red: new objects)"
        )
        files = [str(p.relative_to(ctx.output)) for p in save_figure(fig, out / NAME)]
        self._write_tables(out)
        return files + [f"{NAME}/confusion.csv", f"{NAME}/dissimilar.json"]

    def _write_tables(self, out: Path) -> None:
        objects, numbers = self.objects, [self.ctx.index[o] for o in self.objects]
        write_csv(
            out / "confusion.csv",
            [
                {
                    "panel": key,
                    "object": objects[i],
                    "object_number": numbers[i],
                    "component_object": objects[k],
                    "component_number": numbers[k],
                    "similarity": float(self.matrices[key][i, k]),
                }
                for key in self.keys
                for i in range(len(objects))
                for k in range(len(objects))
            ],
        )
        chosen, index = self.chosen, self.ctx.index
        write_json_atomically(
            out / "dissimilar.json",
            {
                "dissimilar": chosen,
                "dissimilar_numbers": {k: [index[o] for o in v] for k, v in chosen.items()},
                "scores": self.sim["scores"],
                "em": self.sim["em"],
            },
            ConfigError,
            indent=2,
        )

    def headlines(self) -> list[Headline]:
        ctx, chosen, paper_sets = self.ctx, self.chosen, PAPER["fig10_dissimilar"]
        compared = [k for k in self.keys if k in paper_sets]
        if not compared:
            return []
        ours = {k: {ctx.index[o] for o in chosen[k]} for k in compared}
        same = [k for k in compared if set(paper_sets[k]) == ours[k]]
        overlap = [len(set(paper_sets[k]) & ours[k]) for k in compared]
        return [
            Headline(
                NAME,
                "the priors dissimilar to the new objects (per action and for all actions)",
                "; ".join(f"{k} {{{', '.join(map(str, paper_sets[k]))}}}" for k in compared),
                "; ".join(f"{k} {ctx.numbers(chosen[k])}" for k in compared),
                "agrees: the same sets"
                if len(same) == len(compared)
                else f"differs: {len(compared) - len(same)} of {len(compared)} sets differ (mean overlap "
                f"{np.mean(overlap):.1f} of {ctx.scale.dissimilar_count}); expected, the simulated objects are not the "
                "paper's measured ones — Fig. 11 uses the sets found here",
            )
        ]

    def body(self) -> list[str]:
        ctx, sim, paper_sets = self.ctx, self.sim, PAPER["fig10_dissimilar"]
        not_converged = [a for a, e in sim["em"].items() if not e["converged"]]
        return [
            f"Mixture per action: one component per object, initialised at that object's pool observations, "
            f"{COVARIANCE} covariance; EM ≤ 100 iterations, tol 1e-3. Iterations used: "
            + ", ".join(f"{a} {e['n_iter']}" for a, e in sim["em"].items())
            + (
                f" (not converged: {', '.join(not_converged)})"
                if not_converged
                else " (all converged)"
            )
            + ".",
            "",
            "A prior's score is log10 of its largest similarity (mean confusion of both directions, before "
            "rescaling) with any new object; the lowest scores are the dissimilar priors.",
            "",
            markdown_table(
                [
                    "panel",
                    "dissimilar priors",
                    "paper (numbers)",
                    "log10 similarity of each prior (number: score)",
                ],
                [
                    [
                        k,
                        ctx.names(self.chosen[k]),
                        "{" + ", ".join(map(str, paper_sets.get(k, ()))) + "}",
                        ", ".join(f"{ctx.index[o]}: {v:.1f}" for o, v in sim["scores"][k].items()),
                    ]
                    for k in self.keys
                ],
            ),
        ]

    def numbers(self) -> dict[str, Any]:
        paper_sets = PAPER["fig10_dissimilar"]
        same = [
            k
            for k in self.keys
            if k in paper_sets and set(paper_sets[k]) == {self.ctx.index[o] for o in self.chosen[k]}
        ]
        return {
            "dissimilar": self.chosen,
            "scores": self.sim["scores"],
            "em": self.sim["em"],
            "same_as_paper": same,
        }


analyse = _Fig10.analyse
