"""The method's documented alternatives as command-line options, shared by live learning
(``aptkt learn --robot``), learning from a feature table (``aptkt learn --table``), the
real-data benchmark and the reproduction, where they are how the method is checked on another
sensor's data."""

from __future__ import annotations

import argparse
from dataclasses import replace
from typing import Any

from aptkt.learning.active import SELECTIONS
from aptkt.learning.config import KERNELS, LIBRARY_MODELS, READINGS, GPSettings, LearnerConfig
from aptkt.learning.locality import LOCAL_OBJECTS, LOCAL_ROWS
from aptkt.learning.pipeline import FEATURE_SCALES
from aptkt.learning.transfer import CUTOFFS

__all__ = [
    "add_library_model_argument",
    "add_method_arguments",
    "gp_settings",
    "learner_config",
]


#: ``--aux-gate-margin none``: no gate (a margin given as a number otherwise).
NO_GATE = "none"


def _margin_or_none(text: str) -> float | str:
    if text.strip().lower() == NO_GATE:
        return NO_GATE
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"a number (a log Bayes factor) or {NO_GATE}, got {text!r}"
        ) from None


def _by_reading(value: Any) -> str:
    """The default of one choice, which the reading sets: "default: X (paper: Y)"."""
    aptkt, paper = value(LearnerConfig()), value(LearnerConfig.paper())
    return f"default: {aptkt}" + (f" (with --reading paper: {paper})" if paper != aptkt else "")


def add_method_arguments(p: argparse.ArgumentParser) -> None:
    """The method's documented alternatives (docs/method.md). ``--reading`` picks the whole
    set; each other option overrides one setting of it."""
    g = p.add_argument_group(
        "method choices (docs/method.md; defaults: this package's reading of the method)"
    )
    g.add_argument(
        "--reading",
        choices=READINGS,
        default="aptkt",
        help="aptkt: the jointly noise-whitened prior space, one kernel per action (its "
        "amplitude set by the task, its length-scale by every label's evidence), a transfer "
        "only to an object the library recognises as the same (default); paper: the paper's "
        "exact reading (spread-scaled features, each classifier its own ML-II kernel with "
        "fitted weights, Eq. 3's cut-off alone, auxiliary features without an evidence gate)",
    )
    g.add_argument(
        "--selection",
        choices=SELECTIONS,
        help="how the next touch is chosen: error-reduction (the (action, object) pair whose "
        "next touch is expected to remove the most error: the model's error on the pair's "
        "touches so far over their number plus one), paper (AT-LPP, Eq. 4: the pair whose "
        "touches so far are most uncertain) or random; " + _by_reading(lambda c: c.selection),
    )
    g.add_argument(
        "--cutoff",
        choices=CUTOFFS,
        help="same-object: Eq. 3's eps_neg, then the library's model of its objects must "
        "find the new object the same as the source, by log odds above --evidence-margin and "
        "above what its own distinct objects reach; evidence: Eq. 3's eps_neg, then the new "
        "labels' evidence must favour the transfer by --evidence-margin; paper: Eq. 3 alone; "
        + _by_reading(lambda c: c.cutoff),
    )
    g.add_argument(
        "--evidence-margin",
        type=float,
        metavar="M",
        help=f"log odds (same-object) or log Bayes factor (evidence) a transfer must exceed "
        f"(default "
        f"{LearnerConfig.evidence_margin:g}: strong evidence)",
    )
    g.add_argument(
        "--aux-gate-margin",
        type=_margin_or_none,
        metavar="M",
        help="with the auxiliary features (APTKT+aux): the log Bayes factor by which "
        "the new labels' evidence must favour keeping them at an update; none: no gate, they "
        "are always used; "
        + _by_reading(lambda c: NO_GATE if c.aux_gate_margin is None else f"{c.aux_gate_margin:g}"),
    )
    g.add_argument(
        "--kernel",
        choices=KERNELS,
        help="library: one kernel per action, sigma^2 set by the number of new objects and "
        "the length-scale (in noise units) by the evidence of the old and new labels; shared: "
        "one kernel per action, sigma^2 and the length-scale learned on the old and new "
        "objects' observations together; per-classifier: each "
        "classifier its own (a length-scale per modality and the weights of Eq. 1); "
        + _by_reading(lambda c: c.gp.kernel),
    )
    g.add_argument(
        "--prior-feature-scale",
        choices=FEATURE_SCALES,
        help="the metric of a prior built here (a prior loaded from a file keeps its own): "
        "whiten-joint (the old objects' within-object noise, whitened across modalities), "
        "whiten (the same, each modality on its own) or spread (each column z-scored over "
        "the old observations); " + _by_reading(lambda c: c.gp.prior_feature_scale),
    )
    add_library_model_argument(g)


def add_library_model_argument(g: argparse._ActionsContainer, default: str | None = None) -> None:
    """``--library-model``: how the library's model of its old objects is fitted."""
    g.add_argument(
        "--library-model",
        choices=LIBRARY_MODELS,
        default=default,
        help="local: the library's kernel learned on a sample of its objects, each old "
        "object's classifier on the objects nearest to it, a new object compared with the old "
        "ones most like it (its cost does not grow with the library; the same as exact within "
        f"{LOCAL_OBJECTS} objects and {LOCAL_ROWS} observations); exact: every classifier on "
        "every old observation "
        "(its cost grows as the 4th power of the objects); "
        + (
            f"default {default}"
            if default is not None
            else _by_reading(lambda c: c.gp.library_model)
        ),
    )


def gp_settings(args: argparse.Namespace, **fixed: Any) -> GPSettings:
    """The GP settings of the chosen reading with the options given (and ``fixed`` fields)."""
    base = GPSettings.paper() if args.reading == "paper" else GPSettings()
    given = {
        name: value
        for name, value in (
            ("kernel", args.kernel),
            ("prior_feature_scale", args.prior_feature_scale),
            ("library_model", getattr(args, "library_model", None)),
        )
        if value is not None
    }
    return replace(base, **given, **fixed)


def learner_config(args: argparse.Namespace, **fields: Any) -> LearnerConfig:
    """The learner of the chosen reading with the options given, and ``fields`` (budget, seed,
    ...) set as they are."""
    base = LearnerConfig.paper() if args.reading == "paper" else LearnerConfig()
    given = {
        name: value
        for name, value in (
            ("cutoff", args.cutoff),
            ("evidence_margin", args.evidence_margin),
            ("selection", getattr(args, "selection", None)),
        )
        if value is not None
    }
    if args.aux_gate_margin is not None:
        given["aux_gate_margin"] = None if args.aux_gate_margin == NO_GATE else args.aux_gate_margin
    return replace(base, gp=gp_settings(args), **given, **fields)
