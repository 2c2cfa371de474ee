"""Transfer decisions in words: which old object each new one learned from, with which λ, or
which cut-off stopped it and why.

A decision is the plain dictionary a :class:`~aptkt.learning.learner.StepRecord` holds per
action and new object (:meth:`~aptkt.learning.transfer.TransferDecision.as_dict`). The
configuration that made it says which rule applied: Eq. 3's ``eps_neg`` and then, with
``cutoff="same-object"``, the library's log odds that the new object is the old one, or with
``cutoff="evidence"`` the log Bayes factor of the coupling, which must exceed
``evidence_margin``. One text
serves one decision (a live run's steps, the README's example) and the same new object's
decisions over several runs (the demo, learning from a table): outcomes that agree are told
once, with their means and how many runs reached them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from aptkt.errors import InvalidInputError
from aptkt.learning.config import LearnerConfig

__all__ = [
    "Verdict",
    "verdict",
    "describe",
    "describe_runs",
    "by_pair",
    "final_decisions",
    "summary_lines",
    "TRANSFERS",
    "BELOW_EPS_NEG",
    "EVIDENCE_CUTOFF",
]

#: The three outcomes of a decision.
TRANSFERS = "transfers"
BELOW_EPS_NEG = "below eps_neg"
EVIDENCE_CUTOFF = "evidence cut-off"


@dataclass(frozen=True)
class Verdict:
    """One decision, read: the old object it weighed (``candidate``: the transferred one, or
    the one Eq. 3 picked before a cut-off stopped it), its mean probability ``p``, the λ
    transferred (0 without), the second cut-off's log odds for the transfer (``log_bf``; NaN
    where not tested), what they had to exceed (``threshold``: the margin, or more where the
    library's own look-alikes ask for more; NaN where not tested) and the outcome
    (:data:`TRANSFERS`, :data:`BELOW_EPS_NEG` or :data:`EVIDENCE_CUTOFF`)."""

    new_object: str
    candidate: str
    p: float
    lam: float
    log_bf: float
    outcome: str
    threshold: float = math.nan


def verdict(decision: Mapping[str, Any], config: LearnerConfig) -> Verdict:
    """Reads a decision made under ``config``."""
    posterior: Mapping[str, float] = decision.get("mean_posterior", {})
    tested: Mapping[str, float] = decision.get("log_bayes_factor", {})
    if decision.get("source"):
        candidate = str(decision["source"])
        outcome = TRANSFERS
    elif tested:  # passed eps_neg, then the evidence stopped it
        candidate = next(iter(tested))
        outcome = EVIDENCE_CUTOFF
    else:
        pick = max if config._transfer_pick()[0] == "most" else min
        candidate = str(pick(posterior, key=posterior.__getitem__)) if posterior else "?"
        outcome = BELOW_EPS_NEG
    return Verdict(
        new_object=str(decision["new_object"]),
        candidate=candidate,
        p=float(posterior.get(candidate, math.nan)),
        lam=float(decision.get("lambda") or 0.0),
        log_bf=float(tested.get(candidate, math.nan)),
        outcome=outcome,
        threshold=float(decision.get("threshold") or math.nan) if tested else math.nan,
    )


def _mean(values: Sequence[float]) -> float:
    finite = [v for v in values if math.isfinite(v)]
    return sum(finite) / len(finite) if finite else math.nan


def cutoff_words(config: LearnerConfig) -> tuple[str, str]:
    """What the second cut-off's number is called, and the cut-off itself: the library's log
    odds that the new object is the old one (``cutoff="same-object"``) or the log Bayes factor
    of the coupling ("evidence")."""
    if config.cutoff == "same-object":
        return "log odds", "same-object cut-off"
    return "log BF", "evidence cut-off"


def _text(group: Sequence[Verdict], config: LearnerConfig) -> str:
    """One outcome, with the means over the verdicts that reached it."""
    first = group[0]
    p, lam, log_bf = (_mean([getattr(v, k) for v in group]) for k in ("p", "lam", "log_bf"))
    like = config._transfer_pick()[0]
    stat, cutoff = cutoff_words(config)
    bar = _mean([v.threshold for v in group])
    bar_text = f"{bar:.3g}" if math.isfinite(bar) else f"{config.evidence_margin:g}"
    if first.outcome == TRANSFERS:
        bf = f", {stat} {log_bf:.1f} > {bar_text}" if math.isfinite(log_bf) else ""
        return f"<- {first.candidate} (lambda {lam:.2f}{bf})"
    if first.outcome == EVIDENCE_CUTOFF:
        return (
            f"no transfer, {like} like {first.candidate} (p {p:.2f}) but {stat} {log_bf:.1f} "
            f"<= {bar_text} ({cutoff})"
        )
    p_text = _below(p, config.eps_neg)
    return f"no transfer, {like} like {first.candidate} (p {p_text} < eps_neg {config.eps_neg:g})"


def _below(p: float, limit: float) -> str:
    """``p`` with the digits that show it below ``limit`` (0.4996 is not "0.50 < 0.5")."""
    for digits in range(2, 7):
        text = f"{p:.{digits}f}"
        if float(text) < limit:
            return text
    return f"{p:.6g}"


def describe_runs(decisions: Sequence[Mapping[str, Any]], config: LearnerConfig) -> str:
    """One new object's decisions of one action over several runs, e.g. ``box <- cardboard
    (lambda 0.84, log BF 5.2 > 3) in 2/3 runs; no transfer, ... in 1/3 runs``: each outcome and old
    object once, the most frequent first, with mean p, λ and log Bayes factor."""
    verdicts = [verdict(d, config) for d in decisions]
    if not verdicts:
        raise InvalidInputError("no decisions to describe")
    groups: dict[tuple[str, str], list[Verdict]] = {}
    for v in verdicts:
        groups.setdefault((v.outcome, v.candidate), []).append(v)
    ranked = sorted(groups.values(), key=len, reverse=True)  # stable: first seen first
    n = len(verdicts)
    parts = [_text(g, config) + (f" in {len(g)}/{n} runs" if n > 1 else "") for g in ranked]
    name = verdicts[0].new_object
    return name + ("" if parts[0].startswith("<-") else ":") + " " + "; ".join(parts)


def describe(decision: Mapping[str, Any], config: LearnerConfig) -> str:
    """One decision, e.g. ``sponge <- foam (lambda 0.84, log odds 5.2 > 3)`` or ``sponge: no
    transfer, most like foam (p 0.84) but log odds 1.8 <= 3 (same-object cut-off)``."""
    return describe_runs([decision], config)


def final_decisions(
    steps: Sequence[Any],
) -> dict[str, dict[str, dict[str, Any]]]:
    """The decisions in force at the end of a run: per action and new object, the last one
    made (a step records the decisions of the actions it updated; ``steps`` are
    :class:`~aptkt.learning.learner.StepRecord` objects or their ``transfer`` mappings)."""
    final: dict[str, dict[str, dict[str, Any]]] = {}
    for step in steps:
        transfer = step if isinstance(step, Mapping) else step.transfer
        for action, per_object in transfer.items():
            final.setdefault(action, {}).update(per_object)
    return final


def by_pair(
    runs: Sequence[Mapping[str, Mapping[str, Mapping[str, Any]]]],
) -> dict[str, dict[str, list[Mapping[str, Any]]]]:
    """Action -> new object -> the runs' decisions (the runs' :func:`final_decisions`)."""
    pairs: dict[str, dict[str, list[Mapping[str, Any]]]] = {}
    for run in runs:
        for action, decided in run.items():
            for obj, d in decided.items():
                pairs.setdefault(action, {}).setdefault(obj, []).append(d)
    return pairs


def summary_lines(
    runs: Sequence[Mapping[str, Mapping[str, Mapping[str, Any]]]], config: LearnerConfig
) -> list[str]:
    """Per action and new object, what the runs' final decisions (:func:`final_decisions` of
    each run) transferred, or why not: one line each, the action named on its first line."""
    pairs = by_pair(runs)
    width = max((len(a) for a in pairs), default=0)
    lines = []
    for action, objects in pairs.items():
        for k, decisions in enumerate(objects.values()):
            lines.append(f"{action if k == 0 else '':<{width}}  {describe_runs(decisions, config)}")
    return lines
