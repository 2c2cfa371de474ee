"""Fig. 10: object similarity from per-action Gaussian mixture models (paper §5.6), and the
priors dissimilar to the new objects that Fig. 11 transfers from.

Per action, every object's pool observations (never the test set) in the feature space the
learner uses — the feature pipeline fitted on those observations — are clustered as described
in :mod:`aptkt.experiments.similarity`. The "all actions" matrix is the mean of the actions'
confusion matrices, rescaled.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from aptkt.experiments.figures.base import Context, Headline, Plan, Section
from aptkt.experiments.plots import figure, save_figure
from aptkt.experiments.report import PAPER, markdown_table
from aptkt.experiments.similarity import (
    dissimilar_priors,
    fit_mixture,
    log_confusion,
    log_responsibilities,
    rescale,
)
from aptkt.experiments.tables import write_csv
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


def analyse(ctx: Context, rows: Sequence[Mapping[str, Any]]) -> Section:
    out = ctx.figure_dir(NAME)
    sim = similarity(ctx)
    objects, matrices, chosen = sim["objects"], sim["matrices"], sim["dissimilar"]
    numbers = [ctx.index[o] for o in objects]
    keys = list(matrices)
    ncols = min(4, len(keys))
    nrows = math.ceil(len(keys) / ncols)
    fig, axes = figure(
        nrows, ncols, figsize=(4.6 * ncols + 2, 5.2 * nrows), squeeze=False, layout="constrained"
    )
    prior_set = set(ctx.scale.priors)
    names = [ctx.label(o) for o in objects]
    for panel, (ax, key) in enumerate(zip(axes.ravel(), keys)):
        first = panel % ncols == 0  # panels of a row share their rows: one set of row labels
        im = ax.imshow(matrices[key], vmin=0, vmax=1, cmap="viridis")
        ax.set_xticks(range(len(objects)), names, fontsize=6, rotation=90)
        ax.set_yticks(range(len(objects)), names if first else [], fontsize=6)
        if first:
            ax.set_ylabel("row: observations of this object", fontsize=8)
        ax.set_xlabel("column: assigned to this object's mixture component", fontsize=8)
        # The paper's colours: old objects' numbers blue, new objects' red.
        for lab, obj in zip(ax.get_xticklabels() + ax.get_yticklabels(), objects + objects):
            lab.set_color("tab:blue" if obj in prior_set else "tab:red")
        ax.set_title(
            f"{key}: dissimilar {ctx.numbers(chosen[key])}"
            if key != ALL
            else f"average: dissimilar {ctx.numbers(chosen[key])}",
            fontsize=10,
        )
    for ax in axes.ravel()[len(keys) :]:
        ax.set_visible(False)
    fig.colorbar(im, ax=axes.ravel().tolist(), shrink=0.6, label="similarity (rescaled confusion)")
    fig.suptitle(
        "Fig. 10 — object confusion from Gaussian mixture models (blue: prior, red: new objects)"
    )
    files = [str(p.relative_to(ctx.output)) for p in save_figure(fig, out / NAME)]
    write_csv(
        out / "confusion.csv",
        [
            {
                "panel": key,
                "object": objects[i],
                "object_number": numbers[i],
                "component_object": objects[k],
                "component_number": numbers[k],
                "similarity": float(matrices[key][i, k]),
            }
            for key in keys
            for i in range(len(objects))
            for k in range(len(objects))
        ],
    )
    (out / "dissimilar.json").write_text(
        json.dumps(
            {
                "dissimilar": chosen,
                "dissimilar_numbers": {k: [ctx.index[o] for o in v] for k, v in chosen.items()},
                "scores": sim["scores"],
                "em": sim["em"],
            },
            indent=2,
        )
    )
    files += [f"{NAME}/confusion.csv", f"{NAME}/dissimilar.json"]

    paper_sets = PAPER["fig10_dissimilar"]
    compared = [k for k in keys if k in paper_sets]
    same = [k for k in compared if set(paper_sets[k]) == {ctx.index[o] for o in chosen[k]}]
    overlap = [len(set(paper_sets[k]) & {ctx.index[o] for o in chosen[k]}) for k in compared]
    headlines = (
        [
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
        if compared
        else []
    )
    not_converged = [a for a, e in sim["em"].items() if not e["converged"]]
    body = [
        f"Mixture per action: one component per object, initialised at that object's pool observations, "
        f"{COVARIANCE} covariance; EM ≤ 100 iterations, tol 1e-3. Iterations used: "
        + ", ".join(f"{a} {e['n_iter']}" for a, e in sim["em"].items())
        + (f" (not converged: {', '.join(not_converged)})" if not_converged else " (all converged)")
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
                    ctx.names(chosen[k]),
                    "{" + ", ".join(map(str, paper_sets.get(k, ()))) + "}",
                    ", ".join(f"{ctx.index[o]}: {v:.1f}" for o, v in sim["scores"][k].items()),
                ]
                for k in keys
            ],
        ),
    ]
    nums = {"dissimilar": chosen, "scores": sim["scores"], "em": sim["em"], "same_as_paper": same}
    return Section(NAME, TITLE, headlines, "\n".join(body), files, nums)
