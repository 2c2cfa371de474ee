"""Laplace evidence of a fitted one-vs-all classifier's labels, with and without its source.

A classifier with a source task is a joint GP over (source rows, target rows) with the cross
block scaled by λ (Eq. 2). With λ = 0 the two tasks are independent and the joint marginal
likelihood factorises, ``Z(0) = Z_source · Z_target``. Hence, at one set of hyper-parameters θ:

``log Z(λ) − log Z(0)`` is the log Bayes factor of the coupling — how much more probable the
source makes the target's labels than no source does (the evidence cut-off, see
:meth:`aptkt.learning.prior.ActionPrior.transfer_evidence`).

Every value is the Laplace approximation of the core (Rasmussen & Williams §3.4), at the
classifier's own hyper-parameters: the hyper-prior of MAP-II shapes where those lie but is not a
term here.
"""

from __future__ import annotations

import numpy as np

from aptkt.errors import IndexOutOfRangeError, InvalidInputError
from aptkt.gp import LaplaceGPC

__all__ = [
    "at_fitted_hyperparameters",
    "coupling_evidence",
    "uncoupled_evidence",
]


def _row(model: LaplaceGPC, k: int) -> tuple[int, object]:
    """Classifier ``k``'s row of ``theta_`` and the class whose labels are its +1."""
    single = model.theta_.shape[0] == 1
    if not 0 <= k < model.theta_.shape[0]:
        raise IndexOutOfRangeError(f"classifier {k} of {model.theta_.shape[0]}")
    return (0, model.classes_[1]) if single else (k, model.classes_[k])


def _sources(model: LaplaceGPC, label: object) -> list:
    return list(model.sources_.get(label, []))


def _one_source(model: LaplaceGPC, label: object) -> None:
    n = len(_sources(model, label))
    if n != 1:
        raise InvalidInputError(
            f"classifier of class {label!r} has {n} source tasks; the coupling evidence needs "
            "exactly one"
        )


def uncoupled_evidence(model: LaplaceGPC) -> np.ndarray:
    """``log Z(0)`` of every classifier: one evaluation of the whole model with λ, the last
    hyper-parameter (one source), set to 0 in every row (the core evaluates all rows at once,
    so asking row by row would cost a Laplace search per classifier and row)."""
    independent = model.theta_.copy()
    independent[:, -1] = 0.0
    return np.asarray(model.log_marginal_likelihood(independent))


def coupling_evidence(model: LaplaceGPC, k: int) -> float:
    """``log Z(λ) − log Z(0)`` of classifier ``k`` of a fitted model with one source task
    (its fitted hyper-parameters; λ, the last of them, set to 0 for Z(0))."""
    row, label = _row(model, k)
    _one_source(model, label)
    return float(model.log_marginal_likelihood_[row] - uncoupled_evidence(model)[row])


def at_fitted_hyperparameters(model: LaplaceGPC, label: object) -> LaplaceGPC:
    """An unfitted classifier with the fitted hyper-parameters of ``model``'s classifier of
    class ``label``, none of them optimised, and the model's numerical settings."""
    hp = model.hyperparameters_[label]
    names = list(model.modality_names_)
    return LaplaceGPC(
        length_scale=[hp["length_scales"][m] for m in names],
        signal_variance=hp["signal_variance"],
        modality_weights=[hp["modality_weights"][m] for m in names],
        modalities=dict(zip(names, model.modalities_)),
        optimize=False,
        approximation=model.approximation,
        newton_max_iter=model.newton_max_iter,
        newton_tol=model.newton_tol,
        max_jitter=model.max_jitter,
    )
