"""The learner's own estimate of its accuracy, without held-out data.

Every touch after the first round is judged before it is learned: the model of its action
either holds the touched object most probable or not — an honest held-out test of the model of
that moment (prequential evaluation). A judgement of object c made when c had been touched n
times says how often the model errs on c at n touches; the model has since learned more, and,
by the same learning curve the selection rule assumes (:mod:`aptkt.learning.active`: an
object's error falls as 1/n), the error at today's N touches is that error times n/N. Each
object's error is the mean of its judgements carried to today; an object never judged (touched
once, in the first round) takes the mean error of its action's judged objects. The estimate is
one minus the mean error over the objects, averaged over the actions — the quantity the
benchmark measures on held-out touches. It exists once every action has a judged touch.

The judgements favour the objects the selection rule touches most, the confused ones; weighing
every object once, not every judgement, keeps that from lowering the estimate.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from aptkt.errors import InvalidInputError

__all__ = ["AccuracyEstimate"]

Pair = tuple[str, str]


class AccuracyEstimate:
    """Judgements of touches before they were learned, and the accuracy they imply."""

    def __init__(self, actions: Sequence[str], objects: Sequence[str]) -> None:
        self.actions = [str(a) for a in actions]
        self.objects = [str(o) for o in objects]
        if not self.actions or len(self.objects) < 2:
            raise InvalidInputError("an accuracy estimate needs an action and two objects")
        self._pairs = {(a, o) for a in self.actions for o in self.objects}
        #: (action, object) -> [(touches before the judged one, 1 if it was misjudged else 0)]
        self.judgements: dict[Pair, list[tuple[int, float]]] = {}

    def judge(self, action: str, obj: str, touches_before: int, recognised: bool) -> None:
        """One touch judged before it was learned, when ``touches_before`` touches of the pair
        had been learned."""
        if (action, obj) not in self._pairs:
            raise InvalidInputError(f"unknown pair ({action!r}, {obj!r})")
        if touches_before < 1:
            raise InvalidInputError("a judged touch follows at least one learned touch")
        self.judgements.setdefault((action, obj), []).append(
            (int(touches_before), 0.0 if recognised else 1.0)
        )

    def per_action(self, counts: Mapping[Pair, int]) -> dict[str, float]:
        """Each action's estimated accuracy at today's ``counts`` of learned touches per pair
        (NaN for an action none of whose touches was judged yet)."""
        out = {}
        for a in self.actions:
            errors = {}
            for o in self.objects:
                judged = self.judgements.get((a, o))
                if judged:
                    now = counts[(a, o)]
                    errors[o] = float(np.mean([miss * before / now for before, miss in judged]))
            if not errors:
                out[a] = math.nan
                continue
            unjudged = float(np.mean(list(errors.values())))
            out[a] = 1.0 - float(np.mean([errors.get(o, unjudged) for o in self.objects]))
        return out

    def value(self, counts: Mapping[Pair, int]) -> float:
        """The estimated mean accuracy over the actions; NaN until every action has a judged
        touch."""
        per = list(self.per_action(counts).values())
        return float(np.mean(per)) if all(np.isfinite(per)) else math.nan
