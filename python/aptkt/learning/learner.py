"""The APTKT learning process (paper §4.3, Fig. 4) and its baseline.

1. Initial data collection: every action once on every new object.
2. Initial prior-knowledge transfer: for every action, fit the new objects' observation model
   with the multi-modal kernel and, per new object, the dependent kernel on the most related
   prior object (Eq. 2–3); optionally with the prior models' posteriors as an auxiliary
   modality (Eq. 5).
3. Iterate: pick the next (action, object) by uncertainty with ε-exploration (Eq. 4), observe,
   and update only that action's model, weights, λ and transfer — until the budget is spent or
   the models stop improving.

The baseline is the same loop with ``transfer="none"``: nothing of the prior — its feature
transforms are fitted on the new objects' training observations, as in the paper. The control
``transfer="control"`` works in the prior's feature space without transferring, so that APTKT
and the control differ by the transfer alone.
"""

from __future__ import annotations

import math
import time
import zlib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from aptkt.errors import InvalidInputError, InvalidStateError
from aptkt.gp import LaplaceGPC, TransferSource
from aptkt.learning.active import (
    SELECTIONS,
    entropy,
    expected_error_reduction,
    own_error,
    select_next,
)
from aptkt.learning.config import LearnerConfig, lone_observation_signal_variance
from aptkt.learning.environment import Environment
from aptkt.learning.estimate import AccuracyEstimate
from aptkt.learning.evaluation import accuracy, fused_accuracy
from aptkt.learning.kernel import LibraryEvidence, fit_new_objects
from aptkt.learning.observations import Observations, ObservationTable
from aptkt.learning.pipeline import FeaturePipeline, ModalityTransform
from aptkt.learning.prior import AUXILIARY, ActionPrior, PriorKnowledge
from aptkt.learning.transfer import TransferDecision, decide_transfer

__all__ = ["ActionLearner", "APTKT", "LearningRun", "StepRecord"]


class ActionLearner:
    """The new objects' observation model of one action, with its transfer decisions."""

    def __init__(
        self,
        action: str,
        new_objects: Sequence[str],
        config: LearnerConfig,
        prior: ActionPrior | None,
        test: Observations | None = None,
        transforms: Mapping[str, ModalityTransform] | None = None,
        extraction: str | None = None,
    ) -> None:
        self.action = action
        #: The baseline's feature transforms (None: as the observations' extraction says; see
        #: FeaturePipeline).
        self.transforms = transforms
        #: What computes the observations added (the environment's word).
        self.extraction = extraction
        self.new_objects = [str(o) for o in new_objects]
        self.config = config
        self.prior = prior
        self.observations: Observations | None = None
        self.model: LaplaceGPC | None = None
        #: The feature pipeline of the current model's space (set by ``update``).
        self.pipeline: FeaturePipeline | None = None
        self.decisions: dict[str, TransferDecision] = {}
        self.train_entropy: np.ndarray = np.zeros(0)
        #: The current model's posteriors of its own training observations.
        self.train_posteriors: np.ndarray = np.zeros((0, 0))
        #: The feature space of the current model: "prior" (the prior's transforms) or "new"
        #: (fitted on the new objects' training observations, the baseline's).
        self.space: str | None = None
        self.n_updates = 0
        #: Whether the current model uses the auxiliary features, and the log evidence they
        #: added at the last update (with ``auxiliary``).
        self.uses_auxiliary = False
        self.auxiliary_evidence = float("nan")
        self._test = test
        self._test_cache: tuple[FeaturePipeline, np.ndarray] | None = None
        self.test_posteriors: np.ndarray | None = None
        # The current model's test accuracy and hyper-parameters, computed when first asked
        # for: every step records them for every action, and only one action changed.
        self._accuracy: float | None = None
        self._hyperparameters: dict[str, dict[str, float]] | None = None
        # Every old observation in the prior's space (all modalities) and its object; the old
        # objects whose posteriors are the auxiliary features (Eq. 5), fixed at the first
        # update; those old observations' own auxiliary features (leave-one-out).
        self._old: tuple[np.ndarray, np.ndarray] | None = None
        self.auxiliary_objects: list[str] | None = None
        self._old_auxiliary: np.ndarray | None = None
        # The "library" kernel's last log length-scale per model input (with or without the
        # auxiliary features).
        self._log_length_scales: dict[tuple[str, ...], float] = {}

    # -- data --------------------------------------------------------------------------------
    def add(self, obj: str, observation: Mapping[str, np.ndarray], trial: int = 0) -> None:
        one = Observations.single(self.action, obj, observation, trial, self.extraction)
        self.observations = (
            one if self.observations is None else Observations.concat([self.observations, one])
        )

    def count(self, obj: str) -> int:
        return 0 if self.observations is None else int(np.sum(self.observations.objects == obj))

    # -- features ----------------------------------------------------------------------------
    def _pipeline(self) -> FeaturePipeline:
        """The new objects' model space: the prior's (APTKT, the control), where old and new
        observations compare and the metric was learned from many repeats; without a prior
        (the baseline) transforms fitted on the new objects' training observations so far."""
        if self.prior is not None:
            return self.prior.pipeline
        assert self.observations is not None  # update() checks every object was observed
        return FeaturePipeline(self.transforms).fit(self.observations)

    def _features(
        self, obs: Observations, pipeline: FeaturePipeline
    ) -> tuple[np.ndarray, dict[str, list[int]]]:
        X, groups = pipeline.transform(obs)
        return self._model_input(X, groups)

    def _model_input(
        self, X_full: np.ndarray, groups: dict[str, list[int]]
    ) -> tuple[np.ndarray, dict[str, list[int]]]:
        """The new objects' model input from features of every modality: the selected
        modalities, then (Eq. 5) the prior model's posteriors of the observations, computed in
        its own space (which needs every modality)."""
        wanted = self.config.modalities
        names = [m for m in groups if wanted is None or m in wanted]
        if not names:
            raise InvalidInputError(
                f"action {self.action!r} has none of the modalities {list(wanted or [])}; "
                f"it has {list(groups)}"
            )
        cols = [c for m in names for c in groups[m]]
        X = X_full[:, cols]
        out_groups, start = {}, 0
        for m in names:
            out_groups[m] = list(range(start, start + len(groups[m])))
            start += len(groups[m])
        if self.config.auxiliary and self.prior is not None:
            aux = self.prior.posteriors(X_full, self.auxiliary_objects)
            out_groups[AUXILIARY] = list(range(start, start + aux.shape[1]))
            X = np.hstack([X, aux])
        return X, out_groups

    def _old_features(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The old observations ``rows`` (of the prior's) in the model's input space, and
        their objects. Their auxiliary features (Eq. 5) are what the model of the auxiliary
        objects says of an observation it has not seen, as it does of the new ones: its
        leave-one-out posterior for its own observations, its posterior for the others."""
        assert self.prior is not None  # sources and the shared kernel come from the prior
        if self._old is None:
            obs = self.prior.observations
            X_full, _ = self.prior.pipeline.transform(obs)
            self._old = (X_full, np.asarray(obs.objects))
        X_full, objects = self._old
        groups = self.prior.groups
        rows = np.asarray(rows, dtype=np.int64)
        if not self.config.auxiliary:
            return self._model_input(X_full[rows], groups)[0], objects[rows]
        if self._old_auxiliary is None:
            # NaN marks the rows not computed yet.
            self._old_auxiliary = np.full((len(objects), len(self.auxiliary_objects or [])), np.nan)
            mine = self.prior.rows_of(self.auxiliary_objects or [])
            self._old_auxiliary[mine] = self.prior.loo_posteriors(self.auxiliary_objects)
        missing = rows[np.isnan(self._old_auxiliary[rows, 0])]
        if missing.size:
            self._old_auxiliary[missing] = self.prior.posteriors(
                X_full[missing], self.auxiliary_objects
            )
        X = self._model_input(X_full[rows], groups)[0]
        n_aux = self._old_auxiliary.shape[1]
        X[:, X.shape[1] - n_aux :] = self._old_auxiliary[rows]
        return X, objects[rows]

    def _source(
        self, old_object: str, transfer_lambda: float, *, drop_columns: int = 0
    ) -> TransferSource:
        """The source task of one transferred old object: its one-vs-all task (its
        observations +1, the other old objects' of its neighbourhood −1), without the last
        ``drop_columns``."""
        assert self.prior is not None  # only called when transferring
        X, objects = self._old_features(self.prior.neighbourhood(old_object))
        X = X[:, : X.shape[1] - drop_columns]
        mine = objects == old_object
        return TransferSource(
            X, np.where(mine, 1.0, -1.0), transfer_lambda=transfer_lambda, name=old_object
        )

    def _evidence(self, X_prior: np.ndarray, positive: np.ndarray) -> Callable[[str, float], float]:
        """The cut-off's log odds for a transfer into one new object's classifier
        (``positive``: its observations among every new one), in the prior's space: the
        library's posterior odds that they are the old object's (``cutoff="same-object"``), or
        the log Bayes factor of the coupling under the new objects' kernel ("evidence")."""
        prior = self.prior
        assert prior is not None  # only called when transferring
        if self.config.cutoff == "same-object":
            mine = X_prior[np.asarray(positive, dtype=bool)]
            identity = prior.identity
            if identity is None:  # a library without repeats cannot vouch for any transfer
                return lambda old, lam: -math.inf
            return lambda old, lam: identity.log_odds(mine, old)
        kernel = None
        if self._kernel_kind() == "library":
            # The old model's space (every modality, no auxiliary features) at the new objects'
            # amplitude and the length-scale the library favours there.
            rows = prior.sample_rows
            X_old, groups = prior.pipeline.transform(prior.observations.take(rows))
            sv = lone_observation_signal_variance(len(self.new_objects))
            curve = prior.library_evidence(
                X_old, groups, sv, self.config.gp.approximation, rows=rows
            )
            kernel = (sv, curve.best())
        return lambda old, lam: prior.transfer_evidence(X_prior, positive, old, lam, kernel)

    def _cutoff_threshold(self, n: int) -> float:
        """What the second cut-off's log odds must exceed for a new object observed ``n``
        times: ``evidence_margin``, and with the same-object cut-off at least the log odds the
        library's own distinct objects give each other (left out one at a time and presented
        as ``n`` observations: :meth:`ObjectIdentity.impostor_log_odds`) — a library holding
        look-alikes asks for more evidence that a new object is one of its objects."""
        margin = float(self.config.evidence_margin)
        identity = self.prior.identity if self.prior is not None else None
        if self.config.cutoff != "same-object" or identity is None:
            return margin
        return max(margin, identity.impostor_log_odds(n))

    def _kernel_kind(self) -> str:
        """The kernel of the new objects' model: the configured one in the prior's space;
        each classifier its own without a prior (the baseline)."""
        return self.config.gp.kernel if self.prior is not None else "per-classifier"

    def _library_evidence(
        self, groups: Mapping[str, list[int]], drop_columns: int = 0
    ) -> LibraryEvidence:
        """The library's part of the "library" kernel for the model input ``groups`` (the old
        observations' input without its last ``drop_columns`` columns) at the σ² the number of
        new objects sets (:mod:`aptkt.learning.kernel`; cached by the prior)."""
        assert self.prior is not None  # the library kernel lives in the prior's space
        rows = self._library_rows(AUXILIARY in groups)
        X_old, _ = self._old_features(rows)
        X_old = X_old[:, : X_old.shape[1] - drop_columns]
        sv = lone_observation_signal_variance(len(self.new_objects))
        return self.prior.library_evidence(
            X_old, dict(groups), sv, self.config.gp.approximation, rows=rows
        )

    def _library_rows(self, auxiliary: bool) -> np.ndarray:
        """The old observations whose labels weigh in on the new objects' kernel: those of the
        auxiliary objects where the model uses their posteriors, else the library's kernel
        sample (every old observation within the limits of :mod:`aptkt.learning.locality`)."""
        assert self.prior is not None
        if auxiliary:
            return self.prior.rows_of(self.auxiliary_objects or [])
        return self.prior.sample_rows

    # -- model -------------------------------------------------------------------------------
    def update(self, step: int) -> None:
        """Refit this action's model on everything observed so far (λ, transfer)."""
        obs = self.observations
        missing = [o for o in self.new_objects if self.count(o) == 0]
        if missing or obs is None:
            raise InvalidStateError(f"action {self.action!r}: no observation yet of {missing}")
        self._accuracy = self._hyperparameters = None
        cfg = self.config
        pipeline = self._pipeline()
        self.decisions = {}
        if self.prior is not None and (cfg.transfers or cfg.auxiliary):
            # The old models judge the new observations in their own space.
            X_prior = self.prior.pipeline.transform(obs)[0]
        if self.prior is not None and cfg.auxiliary and self.auxiliary_objects is None:
            self.auxiliary_objects = self.prior.auxiliary_objects(X_prior, obs.objects)
        if self.prior is not None and cfg.transfers:
            choice, forced_lambda = cfg._transfer_pick()
            for obj in self.new_objects:
                mine = obs.objects == obj
                # Eq. 3 among the old objects most like the new one (every old object within
                # the limits of aptkt.learning.locality).
                candidates = self.prior.candidates(X_prior[mine])
                self.decisions[obj] = decide_transfer(
                    obj,
                    candidates,
                    self.prior.binary_probabilities(X_prior[mine], candidates),
                    cfg.eps_neg,
                    cfg.transfer,
                    choice=choice,
                    forced_lambda=forced_lambda,
                    evidence=self._evidence(X_prior, mine) if cfg.cutoff != "paper" else None,
                    evidence_margin=self._cutoff_threshold(int(mine.sum())),
                )
        self.model, X = self._fit(pipeline, step)
        self.pipeline = pipeline
        self.space = "prior" if self.prior is not None else "new"
        # The training observations were drawn with the training frequencies: their own
        # posterior keeps them.
        self.train_posteriors = self.model.predict_proba(X)
        self.train_entropy = entropy(self.train_posteriors)
        self.n_updates += 1
        if self._test is not None:
            if self._test_cache is None or self._test_cache[0] is not pipeline:
                self._test_cache = (pipeline, self._features(self._test, pipeline)[0])
            T = self._test_cache[1][:, : self.model.n_features_in_]
            self.test_posteriors = self.model.predict_proba(T)

    def _fit(self, pipeline: FeaturePipeline, step: int) -> tuple[LaplaceGPC, np.ndarray]:
        """This action's model fitted in ``pipeline``'s space on everything observed, with the
        current transfer decisions' sources; and its input rows. In the prior's space with
        ``GPSettings(kernel="shared")`` the old model's one-vs-all task shares the kernel.

        With auxiliary features (Eq. 5) and a gate (``aux_gate_margin``, not None) the model is
        fitted with and without them, and they are kept only when the new labels' Laplace
        evidence favours them by that margin: an extra modality that the labels do not ask for
        only dilutes the kernel (measured: −1.4 pp at one observation per object on real
        data, docs/method.md)."""
        obs = self.observations
        assert obs is not None  # update() checks every object was observed
        X, groups = self._features(obs, pipeline)
        seed = (self.config.seed * 1_000_003 + zlib.crc32(self.action.encode()) + step) % 2**32
        model = self._fit_columns(X, groups, seed, drop_auxiliary=False)
        self.uses_auxiliary = AUXILIARY in groups
        gate = self.config.aux_gate_margin
        if self.uses_auxiliary and gate is not None:
            plain = self._fit_columns(X, groups, seed, drop_auxiliary=True)
            # The new labels' evidence only: the library's own evidence favours the old
            # model's posteriors on its own objects (measured: counted in, the auxiliary
            # features are admitted more often and cost 0.9-1.2 pp on real data).
            gain = float(
                model.log_marginal_likelihood_.sum() - plain.log_marginal_likelihood_.sum()
            )
            self.auxiliary_evidence = gain
            if not gain > gate:
                self.uses_auxiliary = False
                return plain, X[:, : X.shape[1] - len(groups[AUXILIARY])]
        return model, X

    def _fit_columns(
        self, X: np.ndarray, groups: dict[str, list[int]], seed: int, *, drop_auxiliary: bool
    ) -> LaplaceGPC:
        obs = self.observations
        assert obs is not None
        n_aux = len(groups.get(AUXILIARY, [])) if drop_auxiliary else 0
        if n_aux:
            X = X[:, : X.shape[1] - n_aux]
            groups = {m: g for m, g in groups.items() if m != AUXILIARY}
        sources = {
            obj: [
                self._source(old, lam, drop_columns=n_aux) for old, lam in zip(d.sources, d.lambdas)
            ]
            for obj, d in self.decisions.items()
            if d.transfers
        }
        kind = self._kernel_kind()
        if kind == "library":
            key = tuple(groups)
            model = fit_new_objects(
                X,
                obs.objects,
                groups,
                self._library_evidence(groups, n_aux),
                sources=sources,
                approximation=self.config.gp.approximation,
                start=self._log_length_scales.get(key),
            )
            # The next update's search starts where this one ended: one observation more
            # moves the optimum little.
            self._log_length_scales[key] = float(model.theta_[0, 1])
            return model
        shared = kind == "shared"
        model = self.config.gp.make(groups, random_state=seed, shared=shared)
        if shared:
            assert self.prior is not None  # the shared kernel lives in the prior's space
            X_old, y_old = self._old_features(self._library_rows(AUXILIARY in groups))
            old = (X_old[:, : X_old.shape[1] - n_aux], y_old)
            model.fit(X, obs.objects, sources=sources or None, kernel_tasks=[old])
        else:
            model.fit(X, obs.objects, sources=sources or None)
        return model

    def predict_proba(self, obs: Observations) -> np.ndarray:
        """The current model's class posteriors of ``obs`` (columns in ``model.classes_``
        order), seen as the training observations were: in the model's feature space, with the
        auxiliary features where the model kept them."""
        if self.model is None or self.pipeline is None:
            raise InvalidStateError(f"action {self.action!r}: no model yet; call update first")
        X = self._features(obs, self.pipeline)[0]
        # The auxiliary features are the last columns; a gate that refused them dropped them.
        return self.model.predict_proba(X[:, : self.model.n_features_in_])

    def hyperparameters(self) -> dict[str, dict[str, float]]:
        """The fitted hyper-parameters of each new object's classifier (see
        :func:`hyperparameters`)."""
        if self.model is None:
            return {}
        if self._hyperparameters is None:
            self._hyperparameters = hyperparameters(self.model)
        # Copies: each step's record owns its values.
        return {c: dict(hp) for c, hp in self._hyperparameters.items()}

    def judge(
        self, obj: str, observation: Mapping[str, np.ndarray], trial: int = 0
    ) -> tuple[float, bool]:
        """What the current model makes of one observation of ``obj`` it has not learned: the
        posterior it gives ``obj``, and whether ``obj`` is its most probable object."""
        one = Observations.single(self.action, obj, observation, trial, self.extraction)
        classes = [str(c) for c in self.model.classes_] if self.model is not None else []
        if obj not in classes:
            raise InvalidStateError(f"action {self.action!r}: no model of {obj!r} yet")
        row = self.predict_proba(one)[0]
        k = classes.index(obj)
        return float(row[k]), bool(row[k] >= row.max())

    def own_error(self, obj: str) -> float:
        """The current model's error on this action's observations of ``obj``: the posterior
        mass it gives the other objects (:func:`~aptkt.learning.active.own_error`)."""
        if self.observations is None or self.model is None:
            raise InvalidStateError(f"action {self.action!r}: no model yet; call update first")
        classes = [str(c) for c in self.model.classes_]
        mask = self.observations.objects == obj
        return own_error(self.train_posteriors[mask], classes.index(obj))

    def uncertainty(self, obj: str) -> float:
        """UNC(α, c_j): mean entropy of the posterior over this pair's observations."""
        if self.observations is None:
            raise InvalidStateError(f"action {self.action!r}: nothing observed yet")
        mask = self.observations.objects == obj
        return float(self.train_entropy[mask].mean())

    @property
    def test_objects(self) -> np.ndarray:
        if self._test is None:
            raise InvalidStateError("no test observations were given")
        return self._test.objects

    def test_accuracy(self) -> float:
        if self._test is None or self.test_posteriors is None or self.model is None:
            raise InvalidStateError("no test observations were given")
        if self._accuracy is None:
            self._accuracy = accuracy(
                self.test_posteriors,
                [str(c) for c in self.model.classes_],
                [str(o) for o in self._test.objects],
            )
        return self._accuracy


def hyperparameters(model: LaplaceGPC) -> dict[str, dict[str, float]]:
    """Class -> the fitted hyper-parameters of that class's one-vs-all classifier, flat and by
    name: ``signal_variance``, ``length_scale[m]`` and (several modalities) ``weight[m]`` per
    modality m, and ``lambda[s]`` per transfer source s (named by its old object). With two
    classes and no source one classifier serves both, and both list its values."""
    out: dict[str, dict[str, float]] = {}
    for c, hp in model.hyperparameters_.items():
        flat = {"signal_variance": float(hp["signal_variance"])}
        flat.update({f"length_scale[{m}]": float(v) for m, v in hp["length_scales"].items()})
        if len(hp["modality_weights"]) > 1:
            flat.update({f"weight[{m}]": float(v) for m, v in hp["modality_weights"].items()})
        flat.update({f"lambda[{s}]": float(v) for s, v in hp["transfer_lambda"].items()})
        out[str(c)] = flat
    return out


@dataclass
class StepRecord:
    """State after one observation (step 0: after the initial round and transfer)."""

    step: int
    n_observations: int
    action: str | None
    object: str | None
    explored: bool
    #: AT-LPP's UNC of the pair chosen (whatever rule chose it).
    uncertainty: float
    accuracy: dict[str, float]
    mean_accuracy: float
    fused_accuracy: float
    transfer: dict[str, dict[str, Any]]
    seconds: float
    #: action -> class -> hyper-parameter name -> value, every action's current model.
    hyperparameters: dict[str, dict[str, dict[str, float]]] = field(default_factory=dict)
    #: action -> {"space": the feature space its model was fitted in at this step ("prior" or
    #: "new")}, for the actions updated at this step (every action at step 0), as ``transfer``.
    feature_space: dict[str, dict[str, Any]] = field(default_factory=dict)
    #: The error the chosen touch was expected to remove (``selection="error-reduction"``).
    expected_gain: float = math.nan
    #: The posterior the model gave the touched object on the touch before learning it.
    touch_posterior: float = math.nan
    #: Whether the model, before learning the touch, held the touched object most probable.
    touch_recognised: bool | None = None
    #: The learner's own estimate of its mean accuracy (NaN until every action has a touch
    #: judged before it was learned; :class:`~aptkt.learning.estimate.AccuracyEstimate`).
    estimated_accuracy: float = math.nan

    def __repr__(self) -> str:
        if self.action is None:
            what = "initial round"
        else:
            what = f"{self.action} on {self.object}" + (" (explored)" if self.explored else "")
        return (
            f"StepRecord(step {self.step}: {what}; {self.n_observations} observations, mean "
            f"accuracy {self.mean_accuracy:.3f}, fused {self.fused_accuracy:.3f}, "
            f"{self.seconds:.2f} s)"
        )

    def as_row(self) -> dict[str, Any]:
        """Flat: the step's fields, ``accuracy[a]`` per action, the medians of the fitted
        signal variances and length-scales over every classifier, each classifier's
        hyper-parameters as ``hp[action][class].name``, and per updated action the feature
        space of its model (``space[action]``)."""
        row = {
            k: getattr(self, k)
            for k in (
                "step",
                "n_observations",
                "action",
                "object",
                "explored",
                "uncertainty",
                "expected_gain",
                "touch_posterior",
                "touch_recognised",
                "estimated_accuracy",
                "mean_accuracy",
                "fused_accuracy",
                "seconds",
            )
        }
        row.update({f"accuracy[{a}]": v for a, v in self.accuracy.items()})
        for a, chosen in self.feature_space.items():
            row[f"space[{a}]"] = chosen["space"]
        hps = [hp for per in self.hyperparameters.values() for hp in per.values()]
        sv = [hp["signal_variance"] for hp in hps]
        ls = [v for hp in hps for k, v in hp.items() if k.startswith("length_scale[")]
        row["median_signal_variance"] = float(np.median(sv)) if sv else float("nan")
        row["median_length_scale"] = float(np.median(ls)) if ls else float("nan")
        for a, per in self.hyperparameters.items():
            for c, hp in per.items():
                row.update({f"hp[{a}][{c}].{k}": v for k, v in hp.items()})
        return row


@dataclass
class LearningRun:
    """Everything one learning run produced, with the configuration that produced it."""

    config: LearnerConfig
    actions: list[str]
    new_objects: list[str]
    prior_objects: list[str]
    steps: list[StepRecord] = field(default_factory=list)
    stopped_early: bool = False
    #: Why the run stopped before its budget: "pool" (nothing left to observe), "patience" or
    #: "target accuracy"; None where it spent the budget.
    stop_reason: str | None = None

    def __repr__(self) -> str:
        last = self.steps[-1] if self.steps else None
        parts = [
            f"transfer {self.config.transfer!r}",
            f"{len(self.new_objects)} new objects",
            f"{len(self.prior_objects)} prior objects",
            f"actions {', '.join(self.actions)}",
            f"{len(self.steps)} steps" + (", stopped early" if self.stopped_early else ""),
        ]
        if last is not None:
            parts.append(
                f"final mean accuracy {last.mean_accuracy:.3f} after {last.n_observations} "
                "observations"
            )
        return f"LearningRun({'; '.join(parts)})"

    def curve(self) -> dict[str, np.ndarray]:
        return {
            "step": np.array([s.step for s in self.steps]),
            "n_observations": np.array([s.n_observations for s in self.steps]),
            "mean_accuracy": np.array([s.mean_accuracy for s in self.steps]),
            "fused_accuracy": np.array([s.fused_accuracy for s in self.steps]),
        }

    def rows(self) -> list[dict[str, Any]]:
        return [s.as_row() for s in self.steps]


class APTKT:
    """Active prior tactile knowledge transfer (``config.transfer="paper"``) or the baseline.

    ``prior`` may be None only for the baseline (``transfer="none"``), which ignores a prior
    that is given: it uses nothing of it, fitting its feature transforms on the new objects'
    training observations. ``transfer="control"`` uses the prior's feature space (its scaling
    and thermal PCA) without transferring, so that it and APTKT differ by the transfer alone.
    """

    def __init__(
        self,
        config: LearnerConfig | None = None,
        prior: PriorKnowledge | None = None,
        *,
        transforms: Mapping[str, ModalityTransform] | None = None,
    ) -> None:
        """``transforms``: the baseline's feature transforms (None: as the environment's
        observations were computed — this skin's,
        :data:`~aptkt.learning.pipeline.SKIN_TRANSFORMS`, for a robot's or a data set's
        observations, none beyond z-scoring for any others; see
        :func:`~aptkt.learning.pipeline.transforms_of`). A prior's space is the prior's."""
        self.transforms = transforms
        self.config = config or LearnerConfig()
        if self.config.uses_prior and prior is None:
            raise InvalidInputError(
                "transfer and auxiliary features need prior knowledge; pass prior=... "
                "or use LearnerConfig(transfer='none') for the baseline"
            )
        self.prior = prior
        self.learners: dict[str, ActionLearner] = {}

    def run(
        self,
        env: Environment,
        actions: Sequence[str],
        new_objects: Sequence[str],
        test: ObservationTable | None = None,
        on_step: Callable[[StepRecord], None] | None = None,
    ) -> LearningRun:
        cfg = self.config
        actions = [str(a) for a in actions]
        new_objects = [str(o) for o in new_objects]
        if len(new_objects) < 2:
            raise InvalidInputError("learning needs at least two new objects")
        if self.prior is not None and cfg.uses_prior:
            missing = [a for a in actions if a not in self.prior]
            if missing:
                raise InvalidInputError(
                    f"the prior knowledge has no experience of action(s) {missing}"
                )
            overlap = set(new_objects) & set(self.prior.objects)
            if overlap:
                raise InvalidInputError(f"objects {sorted(overlap)} are both prior and new")
        rng = np.random.default_rng(cfg.seed)
        self.learners = {
            a: ActionLearner(
                a,
                new_objects,
                cfg,
                self.prior[a] if self.prior is not None and cfg.uses_prior else None,
                None if test is None else test[a],
                self.transforms,
                getattr(env, "extraction", None),
            )
            for a in actions
        }
        used = self.prior.objects if self.prior is not None and cfg.uses_prior else []
        run = LearningRun(cfg, actions, new_objects, used)
        t0 = time.perf_counter()
        for a in actions:
            for o in new_objects:
                self.learners[a].add(o, env.observe(a, o))
        for a in actions:
            self.learners[a].update(step=0)
        n_obs = len(actions) * len(new_objects)
        self._record(run, 0, n_obs, None, time.perf_counter() - t0, on_step)

        best_unc, stale = np.inf, 0
        estimate = AccuracyEstimate(actions, new_objects)
        for step in range(1, cfg.budget + 1):
            t0 = time.perf_counter()
            unc = self.pair_scores("paper")  # for the record and --patience, whatever the rule
            available = [(a, o) for a in actions for o in new_objects if env.available(a, o)]
            if not available:
                run.stopped_early, run.stop_reason = True, "pool"
                break
            scores = self.pair_scores(cfg.selection) if cfg.selection == "error-reduction" else unc
            sel = select_next(scores, actions, new_objects, cfg.exploration, rng, available)
            learner = self.learners[sel.action]
            touch = env.observe(sel.action, sel.object)
            # What the model made of the touch before learning it: a held-out judgement.
            posterior, recognised = learner.judge(sel.object, touch, trial=step)
            estimate.judge(sel.action, sel.object, learner.count(sel.object), recognised)
            learner.add(sel.object, touch, trial=step)
            learner.update(step=step)
            n_obs += 1
            chosen = (sel.action, sel.object)
            self._record(
                run,
                step,
                n_obs,
                sel,
                time.perf_counter() - t0,
                on_step,
                uncertainty=unc[chosen],
                touch_posterior=posterior,
                touch_recognised=recognised,
                estimated_accuracy=estimate.value(
                    {(a, o): self.learners[a].count(o) for a in actions for o in new_objects}
                ),
                expected_gain=scores[chosen] if cfg.selection == "error-reduction" else math.nan,
            )
            if cfg.patience is not None:
                mean_unc = float(np.mean(list(unc.values())))
                if mean_unc < best_unc - 1e-6:
                    best_unc, stale = mean_unc, 0
                else:
                    stale += 1
                if stale >= cfg.patience:
                    run.stopped_early, run.stop_reason = True, "patience"
                    break
            if (
                cfg.target_accuracy is not None
                and run.steps[-1].estimated_accuracy >= cfg.target_accuracy
            ):
                run.stopped_early, run.stop_reason = True, "target accuracy"
                break
        return run

    def pair_scores(self, selection: str) -> dict[tuple[str, str], float]:
        """Every (action, object) pair's score under a selection rule, from the current models:
        AT-LPP's uncertainty ("paper") or the error one more touch is expected to remove
        ("error-reduction"; :mod:`aptkt.learning.active`). "random" scores nothing (NaN)."""
        if selection not in SELECTIONS:
            raise InvalidInputError(f"selection must be one of {SELECTIONS}, got {selection!r}")
        out = {}
        for a, lrn in self.learners.items():
            for o in lrn.new_objects:
                if selection == "paper":
                    out[(a, o)] = lrn.uncertainty(o)
                elif selection == "error-reduction":
                    out[(a, o)] = expected_error_reduction(lrn.own_error(o), lrn.count(o))
                else:
                    out[(a, o)] = math.nan
        return out

    def _record(
        self,
        run: LearningRun,
        step: int,
        n_obs: int,
        sel: Any,
        seconds: float,
        on_step: Callable[[StepRecord], None] | None,
        *,
        uncertainty: float = math.nan,
        expected_gain: float = math.nan,
        touch_posterior: float = math.nan,
        touch_recognised: bool | None = None,
        estimated_accuracy: float = math.nan,
    ) -> None:
        has_test = all(lrn.test_posteriors is not None for lrn in self.learners.values())
        acc = {a: lrn.test_accuracy() for a, lrn in self.learners.items()} if has_test else {}
        fused = float("nan")
        if has_test and _same_class_order(self.learners):
            first = next(iter(self.learners.values())).model
            assert first is not None  # has_test: every learner has a model
            classes = [str(c) for c in first.classes_]
            fused = fused_accuracy(
                {
                    a: lrn.test_posteriors
                    for a, lrn in self.learners.items()
                    if lrn.test_posteriors is not None
                },
                {a: lrn.test_objects for a, lrn in self.learners.items()},
                classes,
            )
        updated = self.learners[sel.action] if sel is not None else None
        transfer = {
            a: {o: d.as_dict() for o, d in lrn.decisions.items()}
            for a, lrn in self.learners.items()
            if updated is None or lrn is updated
        }
        record = StepRecord(
            step=step,
            n_observations=n_obs,
            action=None if sel is None else sel.action,
            object=None if sel is None else sel.object,
            explored=False if sel is None else sel.explored,
            uncertainty=uncertainty,
            expected_gain=expected_gain,
            touch_posterior=touch_posterior,
            touch_recognised=touch_recognised,
            estimated_accuracy=estimated_accuracy,
            accuracy=acc,
            mean_accuracy=float(np.mean(list(acc.values()))) if acc else float("nan"),
            fused_accuracy=fused,
            transfer=transfer,
            feature_space={
                a: {"space": lrn.space}
                for a, lrn in self.learners.items()
                if updated is None or lrn is updated
            },
            seconds=seconds,
            hyperparameters={a: lrn.hyperparameters() for a, lrn in self.learners.items()},
        )
        run.steps.append(record)
        if on_step is not None:
            on_step(record)


def _same_class_order(learners: Mapping[str, ActionLearner]) -> bool:
    orders = {
        tuple(str(c) for c in lrn.model.classes_)
        for lrn in learners.values()
        if lrn.model is not None
    }
    return len(orders) == 1
