"""The method's documented alternatives as command-line options, shared by live learning
(``aptkt learn --robot``) and learning from a feature table (``aptkt learn --table``), where
they are how the method is checked on another sensor's data."""

from __future__ import annotations

import argparse
from typing import Any

from aptkt.errors import ConfigError
from aptkt.gp import CLASS_PRIORS, LATENT_MEANS
from aptkt.learning.pipeline import FEATURE_SCALES
from aptkt.learning.transfer import CUTOFFS, FEATURE_SPACES, RELATEDNESS, SOURCE_TASKS

__all__ = ["add_method_arguments", "gp_options", "method_options"]


def add_method_arguments(p: argparse.ArgumentParser) -> None:
    """The method's documented alternatives (docs/method.md), for live and table learning:
    each defaults to LearnerConfig's own default."""
    g = p.add_argument_group(
        "method choices (docs/method.md; each default is LearnerConfig's, named first)"
    )
    g.add_argument(
        "--cutoff",
        choices=CUTOFFS,
        help="evidence: Eq. 3's eps_neg, then the new labels' evidence must favour the "
        "transfer; paper: Eq. 3 alone",
    )
    g.add_argument(
        "--evidence-margin",
        metavar="M",
        help="log Bayes factor a transfer must exceed with --cutoff evidence: a number "
        "(default 0: equal prior odds) or lnN (ln of the number of prior objects)",
    )
    g.add_argument(
        "--feature-space",
        choices=FEATURE_SPACES,
        help="where the new objects' models live: auto (the prior's scaling when anything "
        "transfers), covered, prior, new, pooled, or evidence (chosen per update by the new "
        "labels' evidence)",
    )
    g.add_argument(
        "--source",
        choices=SOURCE_TASKS,
        help="the transferred old object's task: one-vs-all (its observations +1, the other "
        "old objects' -1) or positives (its observations only)",
    )
    g.add_argument(
        "--relatedness",
        choices=RELATEDNESS,
        help="p̄ from each old object's own binary classifier (binary) or from the normalised "
        "class posterior (normalised)",
    )
    g.add_argument(
        "--class-prior",
        choices=CLASS_PRIORS,
        help="the new objects' models' class posterior, the baseline's too (with --table also "
        "the prior's, built then; a loaded --prior keeps its own): uniform (each object "
        "equally likely, whatever the learner chose to observe more often; default) or "
        "training (each object as likely as it was observed)",
    )
    g.add_argument(
        "--latent-mean",
        choices=LATENT_MEANS,
        help="the prior mean of every classifier's latent function, for the same models as "
        "--class-prior: zero (far from its data a classifier returns to 1/2; default) or "
        "base-rate (it returns to the rate of positives it was trained at)",
    )

    g.add_argument(
        "--prior-feature-scale",
        choices=FEATURE_SCALES,
        help="how a prior built here z-scores each column (with --table, and the learned "
        "prior a live run saves; a loaded --prior keeps its own): noise (its spread between "
        "repeated observations of one object; default) or spread (its spread over all the old "
        "objects' observations)",
    )


def gp_options(args: argparse.Namespace) -> dict[str, Any]:
    """The GPSettings fields the method options set (those given on the command line)."""
    return {
        field: value
        for field, value in (
            ("class_prior", args.class_prior),
            ("latent_mean", args.latent_mean),
            ("prior_feature_scale", args.prior_feature_scale),
        )
        if value is not None
    }


def method_options(args: argparse.Namespace) -> dict[str, Any]:
    """The LearnerConfig fields the method options set (those given on the command line)."""
    out: dict[str, Any] = {
        field: value
        for field, value in (
            ("cutoff", args.cutoff),
            ("feature_space", args.feature_space),
            ("source", args.source),
            ("relatedness", args.relatedness),
        )
        if value is not None
    }
    margin = args.evidence_margin
    if margin is not None:
        if margin.strip().lower() == "lnn":
            out["evidence_margin"] = None  # LearnerConfig's spelling of ln N_old
        else:
            try:
                out["evidence_margin"] = float(margin)
            except ValueError:
                raise ConfigError(
                    f"--evidence-margin must be a number or lnN, got {margin!r}"
                ) from None
    return out
