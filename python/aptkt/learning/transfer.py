"""From where and how much to transfer (paper §4.6, Eq. 3).

For a new object j and an action α, the prior observation model of α gives, for each of j's
observations, a probability per old object. Their mean ``p̄_i`` measures how much j is like
old object i. The most related old object ``i* = argmax p̄_i`` is transferred with relatedness
``λ = p̄_i*`` unless ``p̄_i* < ε_neg``, in which case nothing is transferred.

The probability is old object i's own one-vs-all classifier's ``p(y=+1 | v)`` (§4.2): a
probability in its own right, so ε_neg asks the same question ("does i's classifier claim j's
observations?") whatever the number of old objects.

Whether the chosen old object is relevant at all (``cutoff``):

* ``"same-object"`` (default, beyond the paper): Eq. 3's ε_neg, and then the library's
  generative model of its objects (:class:`~aptkt.learning.identity.ObjectIdentity`) decides:
  the log posterior odds that the new object's observations so far are the chosen old
  object's — against each other old object and against an object the library does not hold —
  must exceed ``evidence_margin``. A transfer moves the old object's whole region of the feature
  space to the new object; on real materials only a new object that is the old one (the same
  material under another name) gains from it, and the more old objects compete, the more
  evidence one of them needs (each holds 1/N of the prior).
* ``"evidence"`` (beyond the paper): Eq. 3's ε_neg, and then the target task decides.
  ``p̄`` only asks which old object the new one is most like *among the old ones*; a one-vs-all
  classifier trained on the old objects alone also claims observations that are like none of
  them, as long as they lie on its side of the others. The transfer is kept only if it makes
  the new objects' labels more probable: the log Bayes factor of the dependent model (the
  source task coupled by λ) against λ = 0, both under the old classifier's kernel, must exceed
  ``evidence_margin``.
* ``"paper"``: Eq. 3 exactly (``p̄ ≥ ε_neg``).

Modes: ``"paper"`` transfers the single most related old object (Eq. 3); ``"none"`` (the
baseline) and ``"control"`` (the prior's feature space without transfer) never transfer.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from aptkt.errors import InvalidInputError

__all__ = [
    "TransferDecision",
    "mean_posteriors",
    "decide_transfer",
    "TRANSFER_MODES",
    "SOURCE_CHOICES",
    "CUTOFFS",
]

#: "paper": the single most related prior per new object (Eq. 2–3); "none": the paper's
#: baseline (nothing of the prior); "control": the prior's feature space and kernel, no transfer
#: (isolates the transfer itself).
TRANSFER_MODES = ("paper", "none", "control")
#: Which old object Eq. 3 picks: the most related (the method) or, for a stress test of the
#: cut-off, the least related.
SOURCE_CHOICES = ("most", "least")
#: Whether Eq. 3's ε_neg alone decides ("paper") or, after it, the library's model of its
#: objects must hold the new object to be the chosen old one ("same-object") or the target
#: task's evidence must favour the transfer ("evidence"; see the module docstring).
CUTOFFS = ("same-object", "evidence", "paper")


@dataclass(frozen=True)
class TransferDecision:
    """What one new object's classifier of one action receives from the prior knowledge.

    ``sources`` and ``lambdas`` list the transferred old object and its λ (none when nothing
    passes the cut-off).
    ``evidence`` holds, for every old object that passed ε_neg and was tested, the second
    cut-off's log odds for transferring it (the library's log odds that the new object is that
    old one with ``cutoff="same-object"``, the log Bayes factor of the coupling with
    ``"evidence"``; empty otherwise), and ``threshold`` what it had to exceed.
    """

    new_object: str
    old_objects: tuple[str, ...]
    mean_posterior: tuple[float, ...]
    sources: tuple[str, ...] = ()
    lambdas: tuple[float, ...] = ()
    evidence: tuple[tuple[str, float], ...] = ()
    threshold: float | None = None

    @property
    def transfers(self) -> bool:
        return bool(self.sources)

    @property
    def source(self) -> str | None:
        """The (first) transferred old object, or None."""
        return self.sources[0] if self.sources else None

    @property
    def transfer_lambda(self) -> float:
        """λ of the (first) transferred old object, 0 without transfer."""
        return self.lambdas[0] if self.lambdas else 0.0

    def as_dict(self) -> dict:
        return {
            "new_object": self.new_object,
            "source": self.source,
            "lambda": self.transfer_lambda,
            "sources": dict(zip(self.sources, self.lambdas)),
            "mean_posterior": dict(zip(self.old_objects, self.mean_posterior)),
            "log_bayes_factor": dict(self.evidence),
            "threshold": self.threshold,
        }


def mean_posteriors(old_posteriors: np.ndarray) -> np.ndarray:
    """``p̄_i``: the mean over a new object's observations (rows) of the old probabilities."""
    p = np.asarray(old_posteriors, dtype=np.float64)
    if p.ndim != 2 or p.shape[0] == 0:
        raise InvalidInputError(
            f"expected a (n_observations >= 1, n_old_objects) array, got shape {p.shape}"
        )
    return p.mean(axis=0)


def decide_transfer(
    new_object: str,
    old_objects: Sequence[str],
    old_posteriors: np.ndarray,
    eps_neg: float,
    mode: str = "paper",
    *,
    choice: str = "most",
    forced_lambda: float | None = None,
    evidence: Callable[[str, float], float] | None = None,
    evidence_margin: float = 0.0,
) -> TransferDecision:
    """Eq. 3: transfer the most related old object if its mean probability reaches ``eps_neg``.

    ``choice="least"`` and ``forced_lambda`` exist for stress tests of the cut-off: the least
    related old object, and a λ that replaces ``p̄`` once the cut-off has let the transfer
    through (the cut-off always looks at the chosen object's own ``p̄``).

    ``evidence(old_object, λ)``, if given, is the second cut-off's log odds for transferring
    that old object with that λ (see :class:`TransferDecision`); an old object that passed
    ε_neg is then kept only if it exceeds ``evidence_margin``.
    """
    if mode not in TRANSFER_MODES:
        raise InvalidInputError(f"transfer mode must be one of {TRANSFER_MODES}, got {mode!r}")
    if choice not in SOURCE_CHOICES:
        raise InvalidInputError(f"choice must be one of {SOURCE_CHOICES}, got {choice!r}")
    if not 0.0 <= eps_neg <= 1.0:
        raise InvalidInputError(f"eps_neg must lie in [0, 1], got {eps_neg}")
    if forced_lambda is not None and not 0.0 <= forced_lambda <= 1.0:
        raise InvalidInputError(f"forced_lambda must lie in [0, 1], got {forced_lambda}")
    p_bar = mean_posteriors(old_posteriors)
    if p_bar.shape[0] != len(old_objects):
        raise InvalidInputError(
            f"{len(old_objects)} old objects but posteriors over {p_bar.shape[0]}"
        )
    picked: list[int] = []
    if mode == "paper":
        best = int(np.argmax(p_bar) if choice == "most" else np.argmin(p_bar))
        picked = [best] if p_bar[best] >= eps_neg else []
    lambdas = {i: float(p_bar[i] if forced_lambda is None else forced_lambda) for i in picked}
    tested: list[tuple[str, float]] = []
    if evidence is not None:
        kept = []
        for i in picked:
            log_bf = float(evidence(str(old_objects[i]), lambdas[i]))
            tested.append((str(old_objects[i]), log_bf))
            if log_bf > evidence_margin:
                kept.append(i)
        picked = kept
    return TransferDecision(
        new_object=str(new_object),
        old_objects=tuple(str(o) for o in old_objects),
        mean_posterior=tuple(float(v) for v in p_bar),
        sources=tuple(str(old_objects[i]) for i in picked),
        lambdas=tuple(lambdas[i] for i in picked),
        evidence=tuple(tested),
        threshold=float(evidence_margin) if evidence is not None else None,
    )
