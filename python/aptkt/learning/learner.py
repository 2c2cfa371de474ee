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

import time
import zlib
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from aptkt.gp import KernelNotPositiveDefiniteError, LaplaceGPC, TransferSource
from aptkt.learning.active import entropy, select_next
from aptkt.learning.config import LearnerConfig
from aptkt.learning.environment import Environment
from aptkt.learning.evaluation import accuracy, fused_accuracy
from aptkt.learning.evidence import label_evidence, label_evidences
from aptkt.learning.observations import Observations, ObservationTable
from aptkt.learning.pipeline import FeaturePipeline
from aptkt.learning.prior import ActionPrior, PriorKnowledge
from aptkt.learning.transfer import JOINT_SPACES, TransferDecision, decide_transfer

__all__ = ["ActionLearner", "APTKT", "LearningRun", "StepRecord"]

AUXILIARY = "auxiliary"


class ActionLearner:
    """The new objects' observation model of one action, with its transfer decisions."""

    def __init__(
        self,
        action: str,
        new_objects: Sequence[str],
        config: LearnerConfig,
        prior: ActionPrior | None,
        test: Observations | None = None,
    ) -> None:
        self.action = action
        self.new_objects = [str(o) for o in new_objects]
        self.config = config
        self.prior = prior
        self.observations: Observations | None = None
        self.model: LaplaceGPC | None = None
        self.decisions: dict[str, TransferDecision] = {}
        self.train_entropy: np.ndarray = np.zeros(0)
        #: The feature space of the current model ("prior", "new", or with transfers "pooled",
        #: "blended" or "shrunk") and, under
        #: ``feature_space="evidence"`` when the update transferred, each candidate space's
        #: log evidence of the new labels.
        self.space: str | None = None
        self.space_evidence: dict[str, float] = {}
        self.n_updates = 0
        self._test = test
        self._test_cache: tuple[FeaturePipeline, np.ndarray] | None = None
        self.test_posteriors: np.ndarray | None = None
        # The current model's test accuracy and hyper-parameters, computed when first asked
        # for: every step records them for every action, and only one action changed.
        self._accuracy: float | None = None
        self._hyperparameters: dict[str, dict[str, float]] | None = None
        # Every old object's features and objects (the source tasks): in the prior's space,
        # computed once; in the latest other space, until it changes.
        self._old_prior: tuple[FeaturePipeline, np.ndarray, np.ndarray] | None = None
        self._old_cache: tuple[FeaturePipeline, np.ndarray, np.ndarray] | None = None

    # -- data --------------------------------------------------------------------------------
    def add(self, obj: str, observation: Mapping[str, np.ndarray], trial: int = 0) -> None:
        one = Observations.single(self.action, obj, observation, trial)
        self.observations = (
            one if self.observations is None else Observations.concat([self.observations, one])
        )

    def count(self, obj: str) -> int:
        return 0 if self.observations is None else int(np.sum(self.observations.objects == obj))

    # -- features ----------------------------------------------------------------------------
    def _pipeline(self, transfers: bool) -> FeaturePipeline:
        """The new objects' model space: the prior's, fitted on the new objects' training
        observations so far (the baseline's), or fitted on both together ("pooled").
        ``feature_space``: "prior" always the prior's (so does the control), "new" never,
        "auto" the prior's exactly when this update transfers from at least one old object,
        "covered" when it transfers to every new object, "pooled", "blended" and "shrunk"
        the old and new observations' joint transforms when it transfers (the baseline's
        otherwise)."""
        cfg = self.config
        if self.prior is not None and (
            cfg.transfer == "control"
            or cfg.feature_space == "prior"
            or (cfg.feature_space in ("auto", "covered") and transfers)
        ):
            return self.prior.pipeline
        assert self.observations is not None  # update() checks every object was observed
        if self.prior is not None and cfg.feature_space in JOINT_SPACES and transfers:
            # Old and new observations together: "pooled" counts each once, as it enters the
            # Gram matrix; "blended" counts each old object as one observation, "shrunk" weighs
            # them by the new observations' evidence (FeaturePipeline).
            old, new = self.prior.observations, self.observations
            if cfg.feature_space == "blended":
                return FeaturePipeline().fit_blended(old, new)
            if cfg.feature_space == "shrunk":
                return FeaturePipeline().fit_shrunk(old, new)
            return FeaturePipeline().fit(Observations.concat([old, new]))
        return FeaturePipeline().fit(self.observations)

    def _decided_pipeline(self) -> FeaturePipeline:
        """The feature space for the current transfer decisions. "auto": the prior's space when
        anything transfers; "covered": only when every new object has a source (each is like
        an old object, so the prior's transforms were fitted on a population that covers them
        all)."""
        made = [d.transfers for d in self.decisions.values()]
        covered = self.config.feature_space == "covered" and bool(made)
        return self._pipeline(all(made) if covered else any(made))

    def _features(
        self, obs: Observations, pipeline: FeaturePipeline
    ) -> tuple[np.ndarray, dict[str, list[int]]]:
        X, groups = pipeline.transform(obs)
        return self._model_input(X, groups, self._prior_space(obs, pipeline, X))

    def _prior_space(
        self, obs: Observations, pipeline: FeaturePipeline, X: np.ndarray
    ) -> np.ndarray | None:
        """``obs`` in the prior's feature space, where its models judge them (Eq. 3, Eq. 5)."""
        if self.prior is None:
            return None
        return X if pipeline is self.prior.pipeline else self.prior.pipeline.transform(obs)[0]

    def _model_input(
        self, X_full: np.ndarray, groups: dict[str, list[int]], X_prior: np.ndarray | None
    ) -> tuple[np.ndarray, dict[str, list[int]]]:
        """The new objects' model input from features of every modality: the selected
        modalities, then (Eq. 5) the prior model's posteriors of the observations in its own
        space (``X_prior``), which need every modality."""
        wanted = self.config.modalities
        names = [m for m in groups if wanted is None or m in wanted]
        if not names:
            raise ValueError(
                f"action {self.action!r} has none of the modalities {list(wanted or [])}; "
                f"it has {list(groups)}"
            )
        cols = [c for m in names for c in groups[m]]
        X = X_full[:, cols]
        out_groups, start = {}, 0
        for m in names:
            out_groups[m] = list(range(start, start + len(groups[m])))
            start += len(groups[m])
        if self.config.auxiliary and self.prior is not None and X_prior is not None:
            aux = self.prior.posteriors(X_prior)
            out_groups[AUXILIARY] = list(range(start, start + aux.shape[1]))
            X = np.hstack([X, aux])
        return X, out_groups

    def _old_features(self, pipeline: FeaturePipeline) -> tuple[np.ndarray, np.ndarray]:
        """Every old object's observations in the model's input space, and their objects
        (kept while the model space stays the same)."""
        assert self.prior is not None  # sources come from the prior knowledge
        prior_space = pipeline is self.prior.pipeline
        cached = self._old_prior if prior_space else self._old_cache
        if cached is None or cached[0] is not pipeline:
            obs = self.prior.observations
            cached = (pipeline, self._features(obs, pipeline)[0], np.asarray(obs.objects))
            if prior_space:
                self._old_prior = cached
            else:
                self._old_cache = cached
        return cached[1], cached[2]

    def _source(
        self, old_object: str, transfer_lambda: float, pipeline: FeaturePipeline
    ) -> TransferSource:
        """The source task of one transferred old object (``config.source``): its one-vs-all
        task (its observations +1, the other old objects' −1) or its observations alone as
        positives."""
        X, objects = self._old_features(pipeline)
        mine = objects == old_object
        if self.config.source == "positives":
            return TransferSource(X[mine], transfer_lambda=transfer_lambda, name=old_object)
        return TransferSource(
            X, np.where(mine, 1.0, -1.0), transfer_lambda=transfer_lambda, name=old_object
        )

    def _evidence_margin(self) -> float:
        """The log Bayes factor a transfer must exceed: ``config.evidence_margin``, or with
        None ln N_old — prior odds of 1/N_old for "like old object i" against "like none of
        them" (half the prior mass on "like none", the rest spread evenly over the old
        objects)."""
        margin = self.config.evidence_margin
        if margin is not None:
            return margin
        assert self.prior is not None  # only called when transferring
        return float(np.log(len(self.prior.objects)))

    def _evidence(self, X_prior: np.ndarray, positive: np.ndarray) -> Callable[[str, float], float]:
        """The log Bayes factor of a transfer into one new object's classifier (``positive``:
        its observations among every new one), judged in the prior's space by the old model."""
        prior = self.prior
        assert prior is not None  # only called when transferring
        source = self.config.source
        return lambda old, lam: prior.transfer_evidence(X_prior, positive, old, lam, source)

    # -- model -------------------------------------------------------------------------------
    def update(self, step: int) -> None:
        """Refit this action's model on everything observed so far (weights, λ, transfer)."""
        obs = self.observations
        missing = [o for o in self.new_objects if self.count(o) == 0]
        if missing or obs is None:
            raise RuntimeError(f"action {self.action!r}: no observation yet of {missing}")
        self._accuracy = self._hyperparameters = None
        cfg = self.config
        # The old models judge the new observations in their own space.
        X_prior = None if self.prior is None else self.prior.pipeline.transform(obs)[0]
        self.decisions = {}
        if self.prior is not None and X_prior is not None and cfg.transfers:
            related = self.prior.relatedness(X_prior, cfg.relatedness)
            for obj in self.new_objects:
                decision = decide_transfer(
                    obj,
                    self.prior.objects,
                    related[obs.objects == obj],
                    cfg.eps_neg,
                    cfg.transfer,
                    choice=cfg.source_choice,
                    forced_lambda=cfg.forced_lambda,
                    evidence=self._evidence(X_prior, obs.objects == obj)
                    if cfg.cutoff == "evidence"
                    else None,
                    evidence_margin=self._evidence_margin(),
                )
                self.decisions[obj] = decision
        made = [d.transfers for d in self.decisions.values()]
        self.space_evidence = {}
        if cfg.feature_space == "evidence" and any(made):
            pipeline, self.model, X = self._fit_by_evidence(step, X_prior)
        else:
            pipeline = self._decided_pipeline()
            previous = self.model
            self.model, X = self._fit(pipeline, step, X_prior)
            if cfg.cutoff == "fitted" and any(made) and self._reject_by_fitted_evidence(X):
                # The refit starts (warm_start) from the previous update's model, as the first
                # fit did, not from the transfer model it replaces.
                self.model = previous
                pipeline = self._decided_pipeline()
                self.model, X = self._fit(pipeline, step, X_prior)
        self.space = self._space_name(pipeline)
        # The training observations were drawn with the training frequencies: their own
        # posterior keeps them. Scoring them under the uniform prior would make the object the
        # learner observed most look the least certain, and the learner would observe it again
        # (measured: learning curves that stop rising).
        self.train_entropy = entropy(self.model.predict_proba(X, class_prior="training"))
        self.n_updates += 1
        if self._test is not None:
            if self._test_cache is None or self._test_cache[0] is not pipeline:
                self._test_cache = (pipeline, self._features(self._test, pipeline)[0])
            self.test_posteriors = self.model.predict_proba(self._test_cache[1])

    def _fit(
        self, pipeline: FeaturePipeline, step: int, X_prior: np.ndarray | None
    ) -> tuple[LaplaceGPC, np.ndarray]:
        """This action's model fitted in ``pipeline``'s space on everything observed, with the
        current transfer decisions' sources mapped into that space; and its input rows."""
        obs = self.observations
        assert obs is not None  # update() checks every object was observed
        X_full, groups_full = pipeline.transform(obs)
        X, groups = self._model_input(X_full, groups_full, X_prior)
        # Several sources ("multi") share one block kernel B ⊗ k with B = v vᵀ + diag(1 − λ_s²,
        # 0), v = (λ_1 … λ_S, 1): positive semi-definite for every λ_s ∈ [0, 1].
        sources = {
            obj: [self._source(old, lam, pipeline) for old, lam in zip(d.sources, d.lambdas)]
            for obj, d in self.decisions.items()
            if d.transfers
        }
        seed = (self.config.seed * 1_000_003 + zlib.crc32(self.action.encode()) + step) % 2**32
        model = self.config.gp.make(groups, random_state=seed)
        starts = (
            self._starts(list(groups), sources, pipeline)
            if self.config.warm_start is not None
            else None
        )
        kernel_tasks = None
        if (
            self.config.gp.kernel_data == "old+new"
            and self.prior is not None
            and pipeline is self.prior.pipeline
        ):
            kernel_tasks = [self._old_features(pipeline)]
        extra = {} if kernel_tasks is None else {"kernel_tasks": kernel_tasks}
        fitted = model.fit(X, obs.objects, sources=sources or None, hyperparameters=starts, **extra)
        return fitted, X

    def _reject_by_fitted_evidence(self, X: np.ndarray) -> bool:
        """``cutoff="fitted"``: keep a transfer only if, at the fitted models' own
        hyper-parameters, the new object's labels are more probable given the source than
        without it. The fitted transfer model gives ``log p(y | source, θ̂)`` (its log Z minus
        the source task's own at θ̂); the alternative is the same classifier fitted on the new
        observations alone, ``log p(y | θ̂₀)``. Both fits choose their hyper-parameters, so a
        source is judged by everything it does to the new model, its shaping of the
        hyper-parameters included (the blind spot of ``cutoff="evidence"``). Records each log
        Bayes factor in the decisions; returns whether any transfer was dropped."""
        obs = self.observations
        assert obs is not None and self.model is not None
        model = self.model
        alone = self.config.gp.make(
            dict(zip(model.modality_names_, model.modalities_)),
            random_state=int(model.random_state or 0),
        ).fit(X, obs.objects)
        classes = [str(c) for c in model.classes_]
        with_source = label_evidences(model)
        rejected = False
        for obj, decision in list(self.decisions.items()):
            if not decision.transfers:
                continue
            k = classes.index(obj)
            row = 0 if alone.theta_.shape[0] == 1 else k
            log_bf = float(with_source[k] - alone.log_marginal_likelihood_[row])
            keep = np.isfinite(log_bf) and log_bf > self._evidence_margin()
            self.decisions[obj] = replace(
                decision,
                sources=decision.sources if keep else (),
                lambdas=decision.lambdas if keep else (),
                evidence=((decision.sources[0], log_bf),),
            )
            rejected = rejected or not keep
        return rejected

    def _fit_by_evidence(
        self, step: int, X_prior: np.ndarray | None
    ) -> tuple[FeaturePipeline, LaplaceGPC, np.ndarray]:
        """``feature_space="evidence"``: the model fitted in the prior's space and in the new
        objects' own (the baseline's transforms), with the same transfer decisions; kept is the
        one under which the new objects' labels are more probable (``label_evidence``: each
        one-vs-all classifier's labels given its source task, at its own fitted
        hyper-parameters). A candidate whose fit fails or whose evidence is not finite loses;
        a tie, or both failing to give a number, keeps the prior's space ("auto"'s choice)."""
        assert self.prior is not None and self.observations is not None  # it transfers
        candidates = {
            "prior": self.prior.pipeline,
            "new": FeaturePipeline().fit(self.observations),
        }
        fits: dict[str, tuple[FeaturePipeline, LaplaceGPC, np.ndarray]] = {}
        failure: KernelNotPositiveDefiniteError | None = None
        for name, pipeline in candidates.items():
            try:
                model, X = self._fit(pipeline, step, X_prior)
                evidence = label_evidence(model)
            except KernelNotPositiveDefiniteError as exc:
                failure = exc
                self.space_evidence[name] = float("nan")
                continue
            fits[name] = (pipeline, model, X)
            self.space_evidence[name] = evidence
        if not fits:
            assert failure is not None
            raise failure
        return fits[choose_space(self.space_evidence, fits)]

    def _space_name(self, pipeline: FeaturePipeline) -> str:
        """Which feature space the model lives in: "prior" (the prior's transforms), "new" (the
        new objects' own, the baseline's), or when the update transfers under those settings
        "pooled", "blended" or "shrunk" (old and new observations together, see LearnerConfig)."""
        if self.prior is not None and pipeline is self.prior.pipeline:
            return "prior"
        if (
            self.prior is not None
            and self.config.feature_space in JOINT_SPACES
            and any(d.transfers for d in self.decisions.values())
        ):
            return self.config.feature_space
        return "new"

    def _starts(
        self,
        names: list[str],
        sources: Mapping[str, list[TransferSource]],
        pipeline: FeaturePipeline,
    ) -> dict[str, dict[str, Any]]:
        """First starts by class for ``config.warm_start`` (see LearnerConfig). Length-scales
        are distances in a feature space: a start is taken only from a model fitted in the same
        kind of space (the previous update's, if it lived in the space fitted now; the old
        classifier's, only in the prior's space)."""
        mode = self.config.warm_start
        keys = ("signal_variance", "length_scales", "modality_weights")
        out: dict[str, dict[str, Any]] = {}
        previous = self.model
        space = self._space_name(pipeline)
        if mode in ("previous", "both") and previous is not None and self.space == space:
            if list(previous.modality_names_) == names:
                for c, hp in previous.hyperparameters_.items():
                    out[str(c)] = {k: hp[k] for k in keys}
        in_prior_space = self.prior is not None and pipeline is self.prior.pipeline
        if mode in ("source", "both") and self.prior is not None and in_prior_space:
            old_hp = self.prior.model.hyperparameters_
            for obj, lst in sources.items():
                hp = old_hp[max(lst, key=lambda s: s.transfer_lambda or 0.0).name]
                shared = [m for m in names if m in hp["length_scales"]]
                total = sum(hp["modality_weights"][m] for m in shared)
                if not shared or total <= 0:
                    continue
                # A modality the old classifier lacks (the auxiliary one) keeps its
                # data-scaled length-scale and gets an equal share of the weight.
                rest = (len(names) - len(shared)) / len(names)
                weights = {
                    m: (1 - rest) * hp["modality_weights"][m] / total
                    if m in shared
                    else 1 / len(names)
                    for m in names
                }
                out[obj] = {
                    "signal_variance": hp["signal_variance"],
                    "length_scales": {m: hp["length_scales"][m] for m in shared},
                    "modality_weights": weights,
                }
        return out

    def hyperparameters(self) -> dict[str, dict[str, float]]:
        """The fitted hyper-parameters of each new object's classifier (see
        :func:`hyperparameters`)."""
        if self.model is None:
            return {}
        if self._hyperparameters is None:
            self._hyperparameters = hyperparameters(self.model)
        # Copies: each step's record owns its values.
        return {c: dict(hp) for c, hp in self._hyperparameters.items()}

    def uncertainty(self, obj: str) -> float:
        """UNC(α, c_j): mean entropy of the posterior over this pair's observations."""
        if self.observations is None:
            raise RuntimeError(f"action {self.action!r}: nothing observed yet")
        mask = self.observations.objects == obj
        return float(self.train_entropy[mask].mean())

    @property
    def test_objects(self) -> np.ndarray:
        if self._test is None:
            raise RuntimeError("no test observations were given")
        return self._test.objects

    def test_accuracy(self) -> float:
        if self._test is None or self.test_posteriors is None or self.model is None:
            raise RuntimeError("no test observations were given")
        if self._accuracy is None:
            self._accuracy = accuracy(
                self.test_posteriors,
                [str(c) for c in self.model.classes_],
                [str(o) for o in self._test.objects],
            )
        return self._accuracy


def choose_space(evidence: Mapping[str, float], available: Collection[str]) -> str:
    """The candidate space with the larger finite log evidence among ``available``; "prior"
    on a tie or when no candidate has a finite value (then the choice is "auto"'s)."""
    finite = {k: v for k, v in evidence.items() if k in available and np.isfinite(v)}
    if not finite:
        return "prior" if "prior" in available else next(iter(available))
    best = max(finite.values())
    if finite.get("prior") == best:
        return "prior"
    return max(finite, key=lambda k: finite[k])


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
    uncertainty: float
    accuracy: dict[str, float]
    mean_accuracy: float
    fused_accuracy: float
    transfer: dict[str, dict[str, Any]]
    seconds: float
    #: action -> class -> hyper-parameter name -> value, every action's current model.
    hyperparameters: dict[str, dict[str, dict[str, float]]] = field(default_factory=dict)
    #: action -> {"space": the feature space its model was fitted in at this step ("prior",
    #: "new" or "pooled"), "evidence": candidate space -> log evidence of the new labels
    #: (``feature_space="evidence"`` when the update transferred; empty otherwise)}, for the
    #: actions updated at this step (every action at step 0), as ``transfer``.
    feature_space: dict[str, dict[str, Any]] = field(default_factory=dict)

    def as_row(self) -> dict[str, Any]:
        """Flat: the step's fields, ``accuracy[a]`` per action, the medians of the fitted
        signal variances and length-scales over every classifier, each classifier's
        hyper-parameters as ``hp[action][class].name``, and per updated action the feature
        space of its model (``space[action]``) with, under ``feature_space="evidence"``, each
        candidate space's log evidence (``space_evidence[action].prior`` / ``.new``)."""
        row = {
            k: getattr(self, k)
            for k in (
                "step",
                "n_observations",
                "action",
                "object",
                "explored",
                "uncertainty",
                "mean_accuracy",
                "fused_accuracy",
                "seconds",
            )
        }
        row.update({f"accuracy[{a}]": v for a, v in self.accuracy.items()})
        for a, chosen in self.feature_space.items():
            row[f"space[{a}]"] = chosen["space"]
            row.update({f"space_evidence[{a}].{k}": v for k, v in chosen["evidence"].items()})
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
        self, config: LearnerConfig | None = None, prior: PriorKnowledge | None = None
    ) -> None:
        self.config = config or LearnerConfig()
        if self.config.uses_prior and prior is None:
            raise ValueError(
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
            raise ValueError("learning needs at least two new objects")
        if self.prior is not None and cfg.uses_prior:
            missing = [a for a in actions if a not in self.prior]
            if missing:
                raise ValueError(f"the prior knowledge has no experience of action(s) {missing}")
            overlap = set(new_objects) & set(self.prior.objects)
            if overlap:
                raise ValueError(f"objects {sorted(overlap)} are both prior and new")
        rng = np.random.default_rng(cfg.seed)
        self.learners = {
            a: ActionLearner(
                a,
                new_objects,
                cfg,
                self.prior[a] if self.prior is not None and cfg.uses_prior else None,
                None if test is None else test[a],
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
        for step in range(1, cfg.budget + 1):
            t0 = time.perf_counter()
            unc = {(a, o): self.learners[a].uncertainty(o) for a in actions for o in new_objects}
            available = [(a, o) for a in actions for o in new_objects if env.available(a, o)]
            if not available:
                run.stopped_early = True
                break
            sel = select_next(unc, actions, new_objects, cfg.eps_explor, rng, available)
            learner = self.learners[sel.action]
            learner.add(sel.object, env.observe(sel.action, sel.object), trial=step)
            learner.update(step=step)
            n_obs += 1
            self._record(run, step, n_obs, sel, time.perf_counter() - t0, on_step)
            if cfg.patience is not None:
                mean_unc = float(np.mean(list(unc.values())))
                if mean_unc < best_unc - 1e-6:
                    best_unc, stale = mean_unc, 0
                else:
                    stale += 1
                if stale >= cfg.patience:
                    run.stopped_early = True
                    break
        return run

    def _record(
        self,
        run: LearningRun,
        step: int,
        n_obs: int,
        sel: Any,
        seconds: float,
        on_step: Callable[[StepRecord], None] | None,
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
            uncertainty=float("nan") if sel is None else sel.uncertainty,
            accuracy=acc,
            mean_accuracy=float(np.mean(list(acc.values()))) if acc else float("nan"),
            fused_accuracy=fused,
            transfer=transfer,
            feature_space={
                a: {"space": lrn.space, "evidence": dict(lrn.space_evidence)}
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
