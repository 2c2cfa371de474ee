"""Laplace evidence of a fitted one-vs-all classifier's own labels, with and without its source.

A classifier with a source task is a joint GP over (source rows, target rows) with the cross
block scaled by λ (Eq. 2). With λ = 0 the two tasks are independent and the joint marginal
likelihood factorises, ``Z(0) = Z_source · Z_target``. Hence, at one set of hyper-parameters θ:

* ``log Z(λ) − log Z(0)``: the log Bayes factor of the coupling — how much more probable the
  source makes the target's labels than no source does (the evidence cut-off, see
  :meth:`aptkt.learning.prior.ActionPrior.transfer_evidence`);
* ``log Z(λ) − log Z_source = log Z(λ) − log Z(0) + log Z_target``: the target labels'
  probability given the source task's, ``log p(y_target | y_source, θ)`` — what a model of the
  target task predicted of its labels, with its source counted as given data (used to compare
  feature spaces, ``LearnerConfig(feature_space="evidence")``).

Every value is the Laplace approximation of the core (Rasmussen & Williams §3.4), at the
classifier's own hyper-parameters: the hyper-prior of MAP-II shapes where those lie but is not a
term here.
"""

from __future__ import annotations

import numpy as np

from aptkt.gp import LaplaceGPC

__all__ = [
    "at_fitted_hyperparameters",
    "coupling_evidence",
    "label_evidence",
    "label_evidences",
    "target_evidence",
    "uncoupled_evidence",
]


def _row(model: LaplaceGPC, k: int) -> tuple[int, object]:
    """Classifier ``k``'s row of ``theta_`` and the class whose labels are its +1."""
    single = model.theta_.shape[0] == 1
    if not 0 <= k < model.theta_.shape[0]:
        raise IndexError(f"classifier {k} of {model.theta_.shape[0]}")
    return (0, model.classes_[1]) if single else (k, model.classes_[k])


def _sources(model: LaplaceGPC, label: object) -> list:
    return list(model.sources_.get(label, []))


def _one_source(model: LaplaceGPC, label: object) -> None:
    n = len(_sources(model, label))
    if n != 1:
        raise ValueError(
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


def target_evidence(model: LaplaceGPC, k: int) -> float:
    """``log Z_target``: the Laplace log marginal likelihood of classifier ``k``'s own labels
    of the model's training rows alone, at its fitted hyper-parameters (without its source)."""
    row, label = _row(model, k)
    if not _sources(model, label):
        return float(model.log_marginal_likelihood_[row])
    if model.latent_mean != "zero":
        # Z(0) = Z_source(m) · Z_target(m) at the coupled model's mean m, which the base-rate
        # mean takes from source and target labels together; a fit of the target alone would
        # take it from the target's.
        raise ValueError("the target's evidence with a source needs latent_mean='zero'")
    alone = at_fitted_hyperparameters(model, label)
    alone.fit(model.X_train_, np.where(model.y_train_ == label, 1, 0))
    return float(alone.log_marginal_likelihood_[0])


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


def label_evidences(model: LaplaceGPC) -> np.ndarray:
    """``log p(y_k | y_source_k, θ_k)`` of each one-vs-all classifier k of a fitted model:
    its labels of the training rows given its source task (``log Z(λ) − log Z(0) +
    log Z_target``), or its own log marginal likelihood where it has no source. Several sources
    per classifier are refused: with λ = 0 they become independent of each other too, and Z(0)
    is no longer the sources' joint evidence times the target's."""
    n = model.theta_.shape[0]
    out = np.array([target_evidence(model, k) for k in range(n)])
    coupled = []
    for k in range(n):
        row, label = _row(model, k)
        if _sources(model, label):
            _one_source(model, label)
            coupled.append((k, row))
    if coupled:
        # One evaluation of the whole model at λ = 0 serves every classifier.
        log_z0 = uncoupled_evidence(model)
        for k, row in coupled:
            out[k] += model.log_marginal_likelihood_[row] - log_z0[row]
    return out


def label_evidence(model: LaplaceGPC) -> float:
    """``Σ_k log p(y_k | y_source_k, θ_k)`` (``label_evidences``): the classifiers are
    independent given their inputs, so the sum is the log evidence of the whole model's
    labels."""
    return float(label_evidences(model).sum())
