"""Prior tactile knowledge: what the robot learned on earlier ("old") objects, per action —
their feature observations, the feature pipeline fitted on them, and the fitted observation
model (a one-vs-all Laplace GPC over the old objects) with its hyper-parameters.

Saved as one ``.npz`` file of plain arrays plus JSON metadata; loading executes no code
(``allow_pickle=False``) and restores the models exactly at their saved hyper-parameters.
"""

from __future__ import annotations

import json
import zlib
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from aptkt import __version__
from aptkt.errors import PriorFileError, ProblemTooLargeError
from aptkt.files import open_atomically
from aptkt.gp import LaplaceGPC, TransferSource
from aptkt.learning.config import GPSettings
from aptkt.learning.evidence import at_fitted_hyperparameters, uncoupled_evidence
from aptkt.learning.identity import ObjectIdentity, impostor_parts, impostor_table
from aptkt.learning.kernel import LibraryEvidence, library_evidence
from aptkt.learning.locality import CANDIDATES, LOCAL_OBJECTS, kernel_sample, take_objects

if TYPE_CHECKING:
    from aptkt.learning.recognition import CalibrationScores, Recognition
from aptkt.errors import InvalidInputError, UnknownNameError
from aptkt.learning.observations import Observations, ObservationTable
from aptkt.learning.pipeline import FEATURE_SCALES, FeaturePipeline, ModalityTransform
from aptkt.learning.prior_file import FORMAT as _FORMAT
from aptkt.learning.prior_file import check_action, check_calibration, read_members

__all__ = ["ActionPrior", "PriorKnowledge", "AUXILIARY"]

#: The name of the auxiliary features' modality (Eq. 5: the old model's posteriors) in a new
#: objects' model.
AUXILIARY = "auxiliary"


@dataclass
class ActionPrior:
    """The prior experience of one exploratory action.

    ``model`` is the library's one-vs-all observation model fitted on ``sample``, the rows of
    ``observations`` its kernel is learned on (None: every row, as in every library within
    :mod:`aptkt.learning.locality`'s limits). Where it covers the library, Eq. 3, the source
    tasks and the auxiliary features use it directly; beyond, each old object has a classifier
    of its own neighbourhood at the model's kernel (:mod:`aptkt.learning.locality`)."""

    action: str
    observations: Observations
    pipeline: FeaturePipeline
    model: LaplaceGPC
    sample: np.ndarray | None = None
    #: log Z of each source task the evidence test has judged, by old object and kernel.
    _source_evidence: dict[tuple[str, Any], float] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )
    _loo: dict[tuple[str, ...], np.ndarray] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )
    #: The library's evidence over the length-scale, by signal variance, model columns and rows.
    _evidence_curves: dict[tuple[Any, ...], LibraryEvidence] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )
    #: Each old object's classifier of its neighbourhood (beyond the limits), by object.
    _local: dict[str, LaplaceGPC] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )
    _neighbourhoods: dict[str, np.ndarray] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )
    #: The one-vs-all models of sets of old objects (the auxiliary features' objects).
    _models_of: dict[tuple[str, ...], LaplaceGPC] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )

    def __repr__(self) -> str:
        obs = self.observations
        return (
            f"ActionPrior({self.action!r}: {len(self.objects)} objects, {len(obs)} observations, "
            f"columns {_columns(obs)})"
        )

    @cached_property
    def objects(self) -> list[str]:
        """Every old object of the action, sorted (the model's classes where it covers them)."""
        return [str(o) for o in np.unique(np.asarray(self.observations.objects).astype(str))]

    @property
    def sample_rows(self) -> np.ndarray:
        """The rows of ``observations`` the model is fitted on."""
        return np.arange(len(self.observations)) if self.sample is None else self.sample

    @property
    def covers_library(self) -> bool:
        """Whether ``model`` holds every old observation (then it is the exact model)."""
        return self.sample is None or self.sample.size == len(self.observations)

    def features(self, obs: Observations) -> tuple[np.ndarray, dict[str, list[int]]]:
        """Observations in this prior's feature space."""
        return self.pipeline.transform(obs)

    @cached_property
    def groups(self) -> dict[str, list[int]]:
        """The feature space's columns by modality."""
        return self.pipeline.transform(self.observations.take(np.arange(1)))[1]

    # -- which old objects a new one is compared with ----------------------------------------
    def candidates(self, X: np.ndarray) -> list[str]:
        """The old objects Eq. 3 compares observations ``X`` (rows in this prior's space, of one
        object) with: every old object where the model covers the library, else the
        :data:`~aptkt.learning.locality.CANDIDATES` most likely, under the identity model, to
        have given them. In the library's order."""
        if self.covers_library or self.identity is None:
            return self.objects
        near = self.identity.nearest(X, CANDIDATES)
        return [self.identity.objects_[k] for k in np.sort(near)]

    def neighbourhood(self, old_object: str) -> np.ndarray:
        """The rows of ``old_object``'s one-vs-all task: every row where the model covers the
        library, else the rows of the object and of the library's objects nearest to it under
        the identity model, within :mod:`aptkt.learning.locality`'s limits."""
        if self.covers_library or self.identity is None:
            return np.arange(len(self.observations))
        if old_object not in self._neighbourhoods:
            identity = self.identity
            k = identity.objects_.index(old_object)
            old, _ = identity.log_likelihoods(self._training_X[identity.rows_of(k)])
            old[k] = np.inf  # the object itself first, whatever its own noise
            order = np.argsort(-old, kind="stable")
            self._neighbourhoods[old_object] = take_objects(
                order, [identity.rows_of(j) for j in range(len(identity.objects_))]
            )
        return self._neighbourhoods[old_object]

    def auxiliary_objects(self, X: np.ndarray, objects: np.ndarray) -> list[str]:
        """The old objects whose posteriors are the auxiliary features (Eq. 5) of a task whose
        observations so far are ``X`` (this prior's space) of ``objects``: every old object
        where the model covers the library, else the old objects nearest the new ones — each new
        object's nearest in turn, under the identity model — within the limits. In the
        library's order."""
        if self.covers_library or self.identity is None:
            return self.objects
        identity = self.identity
        labels = np.asarray(objects).astype(str)
        ranked = [
            identity.nearest(X[labels == o], LOCAL_OBJECTS) for o in dict.fromkeys(labels.tolist())
        ]
        order = list(dict.fromkeys(int(k) for row in zip(*ranked) for k in row))
        rows = take_objects(order, [identity.rows_of(j) for j in range(len(identity.objects_))])
        return sorted(set(np.asarray(self.observations.objects)[rows].astype(str).tolist()))

    # -- the old models ----------------------------------------------------------------------
    def binary_probabilities(
        self, X: np.ndarray, objects: Sequence[str] | None = None
    ) -> np.ndarray:
        """Each old object's own binary classifier's ``p(y=+1 | v)``, (n, objects), for
        ``objects`` (default: every old object); rows need not sum to 1 (paper §4.2). With two
        old objects there is one classifier, and these are the class posterior. Beyond the
        limits each object's classifier is the one of its neighbourhood."""
        names = self.objects if objects is None else [str(o) for o in objects]
        if self.covers_library:
            p = binary_probabilities(self.model, X)
            where = {str(c): k for k, c in enumerate(self.model.classes_)}
            return p[:, [where[o] for o in names]]
        out = np.empty((np.atleast_2d(X).shape[0], len(names)))
        for k, o in enumerate(names):
            out[:, k] = self._classifier(o).predict_proba_binary(X)[:, 1]
        return out

    def _classifier(self, old_object: str) -> LaplaceGPC:
        """``old_object``'s classifier of its neighbourhood (+1 its rows, −1 its neighbours')."""
        if old_object not in self._local:
            rows = self.neighbourhood(old_object)
            y = (np.asarray(self.observations.objects)[rows] == old_object).astype(np.int64)
            self._local[old_object] = self._fitted_like_model(self._training_X[rows], y)
        return self._local[old_object]

    def _fitted_like_model(self, X: np.ndarray, y: np.ndarray) -> LaplaceGPC:
        """A model of the rows ``X`` labelled ``y`` with the library model's kernel: at its
        fitted hyper-parameters where one kernel serves every classifier, fitted as the model
        was (each classifier its own kernel) otherwise."""
        if self.model.kernel == "shared":
            return at_fitted_hyperparameters(self.model, self.model.classes_[0]).fit(X, y)
        from sklearn.base import clone

        return clone(self.model).fit(X, y)

    def model_of(self, objects: Sequence[str]) -> LaplaceGPC:
        """The one-vs-all model of the old ``objects`` alone (their rows), at the library model's
        kernel: the library model itself where it covers them all."""
        key = tuple(sorted(str(o) for o in objects))
        if self.covers_library and list(key) == self.objects:
            return self.model
        if key not in self._models_of:
            rows = self.rows_of(key)
            labels = np.asarray(self.observations.objects)[rows]
            self._models_of[key] = self._fitted_like_model(self._training_X[rows], labels)
        return self._models_of[key]

    def rows_of(self, objects: Sequence[str]) -> np.ndarray:
        """The rows of the given old objects, in the library's order."""
        return np.flatnonzero(np.isin(np.asarray(self.observations.objects).astype(str), objects))

    def posteriors(self, X: np.ndarray, objects: Sequence[str] | None = None) -> np.ndarray:
        """``p(c_i^old | v)`` for feature rows already in this prior's space, (n, objects):
        the class posterior (one-vs-all probabilities normalised to sum to 1) of the model of
        ``objects`` (default: every old object)."""
        return self.model_of(self.objects if objects is None else objects).predict_proba(X)

    def loo_posteriors(self, objects: Sequence[str] | None = None) -> np.ndarray:
        """``p(c_i^old | v)`` of every observation of ``objects`` (default: every old object;
        their rows in the library's order) by the model of those objects fitted without it: its
        leave-one-out posterior, from each classifier's Laplace approximation with that
        observation's own likelihood term removed (the cavity distribution, whose predictive
        probability is taken as for a new observation). A model's posterior of its own training
        observations is nearly one-hot, and as auxiliary features (Eq. 5) of the old
        observations it would tell the shared kernel that the old model separates everything;
        the new observations' auxiliary features are out of sample, so the old ones must be
        too."""
        key = tuple(sorted(self.objects if objects is None else [str(o) for o in objects]))
        if key not in self._loo:
            model = self.model_of(key)
            self._loo[key] = leave_one_out_posteriors(model, self._training_X[self.rows_of(key)])
        return self._loo[key]

    def training_features(self) -> np.ndarray:
        return self.pipeline.transform(self.observations)[0]

    @cached_property
    def _training_X(self) -> np.ndarray:
        """The old observations in this prior's space, computed once (the evidence test reads
        them at every update)."""
        return self.training_features()

    @cached_property
    def identity(self) -> ObjectIdentity | None:
        """The library's generative model of its objects in this prior's feature space: which
        old object, if any, observations are of (:mod:`aptkt.learning.identity`). None when no
        object was observed twice: without repeats the library knows no noise to judge by."""
        objects = np.asarray(self.observations.objects)
        if len(set(objects.tolist())) == objects.size:
            return None
        return ObjectIdentity(self._training_X, objects)

    def library_evidence(
        self,
        X: np.ndarray,
        groups: Mapping[str, list[int]],
        signal_variance: float,
        approximation: str = "erf",
        rows: np.ndarray | None = None,
    ) -> LibraryEvidence:
        """The old objects' summed evidence as a function of the shared length-scale at a fixed
        ``signal_variance``, for the old observations ``X`` as a model sees them (its columns
        ``groups``) — the library's rows ``rows`` (default: every row): the library's part of
        the "library" kernel (:mod:`aptkt.learning.kernel`), computed once per signal
        variance, columns and rows."""
        rows = np.arange(len(self.observations)) if rows is None else np.asarray(rows)
        key = (
            round(float(signal_variance), 12),
            tuple((m, tuple(c)) for m, c in groups.items()),
            rows.size,
            zlib.crc32(np.ascontiguousarray(rows, dtype=np.int64).tobytes()),
        )
        if key not in self._evidence_curves:
            self._evidence_curves[key] = library_evidence(
                X,
                np.asarray(self.observations.objects)[rows],
                groups,
                signal_variance,
                approximation=approximation,
            )
        return self._evidence_curves[key]

    def features_of(self, old_object: str) -> np.ndarray:
        return self.pipeline.transform(self.observations.of_objects([old_object]))[0]

    def transfer_evidence(
        self,
        X_new: np.ndarray,
        positive: np.ndarray,
        old_object: str,
        transfer_lambda: float,
        kernel: tuple[float, float] | None = None,
    ) -> float:
        """The log Bayes factor of transferring ``old_object`` into a new object's classifier.

        ``X_new``: every new observation of this action so far, in this prior's feature space;
        ``positive``: which of them belong to the new object (its binary task's +1 labels).
        Model 1 couples the new object's latent function to the old object's one-vs-all task
        (its observations +1, the other old objects' of its neighbourhood −1) by λ, as Eq. 2
        does; model 0 is the same with λ = 0 (the two tasks independent). Both use ``kernel`` —
        (σ², length-scale) of the new objects' model, equal modality weights — or without it
        the old object's own classifier's hyper-parameters, and no hyper-parameter is fitted, so
        the factor compares the two hypotheses only. With λ = 0 the joint marginal likelihood is
        the source's times the target's, so ``log Z(λ) − log Z(0) = log p(y_new | source, λ) −
        log p(y_new)``: how much more probable the source makes the new labels (> 0: the
        transfer is supported). Laplace approximations throughout.
        """
        rows = self.neighbourhood(old_object)
        X_old = self._training_X[rows]
        mine = np.asarray(self.observations.objects)[rows] == old_object
        task = TransferSource(X_old, np.where(mine, 1.0, -1.0), transfer_lambda=transfer_lambda)
        positive = np.asarray(positive, dtype=bool)
        if positive.shape != (X_new.shape[0],) or positive.all() or not positive.any():
            raise InvalidInputError("positive must mark some, not all, of the new observations")
        labels = np.where(positive, 1, 0)
        reference = self.model if self.covers_library else self._classifier(old_object)
        label: Any = old_object if self.covers_library else 1

        def classifier() -> LaplaceGPC:
            # Fresh classifiers rather than a clone: scikit-learn's clone inspects the
            # constructor's signature, a tenth of a decision's time.
            if kernel is None:
                return at_fitted_hyperparameters(reference, label)
            names = list(self.model.modality_names_)
            return LaplaceGPC(
                length_scale=kernel[1],
                signal_variance=kernel[0],
                modalities=dict(zip(names, self.model.modalities_)),
                optimize=False,
                approximation=self.model.approximation,
            )

        coupled = classifier().fit(X_new, labels, sources={1: task})
        row = int(np.flatnonzero(coupled.classes_ == 1)[0])
        # log Z(0) = log Z_source + log Z_target. The source's factor is the same at every
        # update (the same kernel, the same old rows): it is computed once, from the first
        # joint model at λ = 0, and only the small target task is evaluated afresh.
        alone = classifier().fit(X_new, labels)
        target = float(alone.log_marginal_likelihood_[0])
        key = (old_object, kernel)
        if key not in self._source_evidence:
            self._source_evidence[key] = uncoupled_evidence(coupled)[row] - target
        return float(coupled.log_marginal_likelihood_[row] - self._source_evidence[key] - target)


#: Copies of a library's observations its build and calibration hold at once (the observations,
#: their features, the identity model's and the calibration's), and the bytes of one block of
#: the calibration's (touches × objects) matrices with their temporaries: measured at 10,000
#: objects × 12 observations (peak 456 MB with 200 MB of libraries loaded).
LIBRARY_COPIES = 16
CALIBRATION_BYTES = 8 * 8 * 2_000_000


def library_bytes(observations: int, columns: int, objects: int) -> int:
    """About how much memory building a local library of that size needs beyond the program."""
    from aptkt.learning.identity import IMPOSTOR_COMPETITORS

    return (
        LIBRARY_COPIES * observations * columns * 8
        + objects * (IMPOSTOR_COMPETITORS + 4 * columns) * 8
        + CALIBRATION_BYTES
    )


def check_library_memory(action: str, obs: Observations) -> None:
    """A library too large for the memory this process may still allocate is refused before
    its models are fitted, with its size (:class:`~aptkt.errors.ProblemTooLargeError`)."""
    from aptkt import _core
    from aptkt.learning.identity import human_bytes

    columns = sum(v.shape[1] for v in obs.modalities.values())
    needed = library_bytes(len(obs), columns, len(obs.object_names))
    available = _core.available_memory()
    if available is not None and needed > available:
        raise ProblemTooLargeError(
            f"action {action!r}: a library of {len(obs.object_names)} objects and {len(obs)} "
            f"observations of {columns} columns needs about {human_bytes(needed)} of memory to "
            f"build, and {human_bytes(available)} are available here; build it where more "
            "memory is (its file holds every observation), or from fewer objects or trials"
        )


def leave_one_out_posteriors(model: LaplaceGPC, X: np.ndarray) -> np.ndarray:
    """The class posterior of each training row of ``model`` (fitted on ``X``, without
    sources) by the model without that row: per binary classifier, the Laplace posterior of
    the row's latent value, N(f̂, v), divided by the row's Gaussian likelihood site (precision
    W = π̂(1 − π̂), linear coefficient W f̂ + t − π̂) gives the cavity N(μ₋, 1/τ₋); its
    probability ∫ sigmoid(f) N(f | μ₋, 1/τ₋) df (probit approximation) is normalised over the
    classifiers as :meth:`LaplaceGPC.predict_proba` does."""
    mean, var = model.latent(X)
    mean = np.asarray(mean, dtype=np.float64).reshape(X.shape[0], -1)
    var = np.asarray(var, dtype=np.float64).reshape(X.shape[0], -1)
    classes = np.asarray(model.classes_)
    y = np.asarray(model.y_train_)
    single = mean.shape[1] == 1
    positives = [classes[1]] if single else list(classes)
    t = np.column_stack([(y == c).astype(np.float64) for c in positives])
    pi = 1.0 / (1.0 + np.exp(-mean))
    w = pi * (1.0 - pi)
    with np.errstate(divide="ignore", invalid="ignore"):
        tau = 1.0 / var - w
        mu = (mean / var - w * mean - (t - pi)) / tau
    # A row whose site carries all its precision (tau ≤ 0 only by rounding) keeps its posterior.
    bad = ~(np.isfinite(tau) & (tau > 0) & np.isfinite(mu))
    s2 = np.where(bad, var, 1.0 / np.where(bad, 1.0, tau))
    mu = np.where(bad, mean, mu)
    p = 1.0 / (1.0 + np.exp(-mu / np.sqrt(1.0 + np.pi * s2 / 8.0)))
    if single:
        return np.column_stack([1.0 - p[:, 0], p[:, 0]])
    total = p.sum(axis=1, keepdims=True)
    return np.where(total > 0, p / np.where(total > 0, total, 1.0), 1.0 / p.shape[1])


def _columns(obs: Observations) -> str:
    """A modality's columns in a repr: ``force 1, thermal 6``."""
    return ", ".join(f"{m} {v.shape[1]}" for m, v in obs.modalities.items())


def binary_probabilities(model: LaplaceGPC, X: np.ndarray) -> np.ndarray:
    """Each one-vs-all classifier's own ``p(y=+1 | x)`` of a fitted :class:`LaplaceGPC`."""
    return model.predict_proba_binary(X)


class PriorKnowledge:
    """Prior experiences of several actions over the same old objects."""

    def __init__(
        self, actions: Mapping[str, ActionPrior], metadata: Mapping[str, Any] | None = None
    ) -> None:
        if not actions:
            raise InvalidInputError("prior knowledge needs at least one action")
        self.actions: dict[str, ActionPrior] = dict(actions)
        self.metadata: dict[str, Any] = dict(metadata or {})
        #: The library's calibration scores (recognition), computed once or read from its file.
        self.calibration_scores: CalibrationScores | None = None

    def __repr__(self) -> str:
        actions = [
            f"{name} ({len(p.observations)} observations; {_columns(p.observations)})"
            for name, p in self.actions.items()
        ]
        if len(actions) > 4:
            actions = [*actions[:3], f"... {len(actions) - 3} more"]
        gp = self.metadata.get("gp")
        model = gp.get("library_model") if isinstance(gp, dict) else None
        said = f", library model {model}" if model else ""
        return (
            f"PriorKnowledge({len(self.objects)} objects, {len(self.actions)} "
            f"action{'s' if len(self.actions) != 1 else ''}: {', '.join(actions)}{said})"
        )

    def __getitem__(self, action: str) -> ActionPrior:
        try:
            return self.actions[action]
        except KeyError:
            raise UnknownNameError(
                f"no prior knowledge for action {action!r}; known: {sorted(self.actions)}"
            ) from None

    def __contains__(self, action: object) -> bool:
        return action in self.actions

    @property
    def objects(self) -> list[str]:
        return sorted({o for a in self.actions.values() for o in a.objects})

    @classmethod
    def build(
        cls,
        table: ObservationTable,
        objects: Iterable[str] | None = None,
        *,
        gp: GPSettings | None = None,
        transforms: Mapping[str, ModalityTransform] | None = None,
        seed: int = 0,
        progress: Any = None,
    ) -> PriorKnowledge:
        """Fit the observation model of every action in ``table`` on the given old objects."""
        gp = gp or GPSettings()
        actions = {}
        for k, (name, obs) in enumerate(table.items()):
            if objects is not None:
                obs = obs.of_objects(objects)
            check_library_memory(name, obs)
            if len(obs.object_names) < 2:
                raise InvalidInputError(
                    f"action {name!r}: prior knowledge needs at least two old objects"
                )
            pipeline = FeaturePipeline(transforms).fit(obs, scale=gp.prior_feature_scale)
            X, groups = pipeline.transform(obs)
            # The old objects' own model: one kernel for their classifiers, learned on them —
            # on a sample of them beyond the limits of :mod:`aptkt.learning.locality`.
            sample = (
                kernel_sample(obs.objects, seed + k)
                if gp.library_model == "local"
                else np.arange(len(obs))
            )
            shared = gp.kernel in ("library", "shared")
            try:
                model = gp.make(groups, random_state=seed + k, shared=shared).fit(
                    X[sample], np.asarray(obs.objects)[sample]
                )
            except ProblemTooLargeError as exc:
                # Refused before anything was allocated: say what would fit.
                raise ProblemTooLargeError(
                    f"action {name!r}: a library of {len(obs.object_names)} objects and "
                    f"{len(obs)} observations is too large for library_model={gp.library_model!r} "
                    f"here ({exc}); use library_model 'local' (--library-model local, the "
                    "default), whose cost does not grow with the library"
                ) from None
            kept = None if sample.size == len(obs) else sample
            actions[name] = ActionPrior(name, obs, pipeline, model, kept)
            if progress is not None:
                progress.update(1)
        meta = {"software_version": __version__, "seed": seed, "gp": gp.to_dict()}
        return cls(actions, meta)

    # -- persistence ---------------------------------------------------------------------------
    def save(self, path: str | Path) -> Path:
        path = Path(path)
        arrays: dict[str, Any] = {}
        for i, prior in enumerate(self.actions.values()):
            p = f"a{i}"
            arrays.update(prior.observations.to_npz(f"{p}/obs"))
            arrays.update(prior.pipeline.state(f"{p}/pipeline"))
            for key, value in prior.model.state().items():
                arrays[f"{p}/model/{key}"] = value
            if prior.sample is not None:
                arrays[f"{p}/sample"] = np.asarray(prior.sample, dtype=np.int64)
        self.precompute()
        for i, prior in enumerate(self.actions.values()):
            if prior.identity is not None and prior.identity.impostors is not None:
                arrays[f"a{i}/impostors"] = prior.identity.impostors
        scores = self.scores()
        arrays["calibration/held_in"] = scores.held_in
        arrays["calibration/held_out"] = scores.held_out
        meta = {
            "format": _FORMAT,
            "actions": list(self.actions),
            "metadata": self.metadata,
            "calibration_touches": scores.touches,
        }
        # What computed each action's observations (files without it: not said).
        said = {
            a: p.observations.extraction
            for a, p in self.actions.items()
            if p.observations.extraction is not None
        }
        if said:
            meta["extractions"] = said
        # Which actions' metric whitens across modalities: a file that lost that member is
        # damaged, not a metric of another kind (files without the list: not said).
        meta["joint"] = [a for a, p in self.actions.items() if p.pipeline.joint_ is not None]
        arrays["meta"] = np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)
        path.parent.mkdir(parents=True, exist_ok=True)
        with open_atomically(path, PriorFileError, "wb") as fh:
            np.savez_compressed(fh, **arrays)
        return path

    @classmethod
    def load(cls, path: str | Path) -> PriorKnowledge:
        """Read a prior file; every member is checked first (see :mod:`aptkt.learning.prior_file`):
        a file that is not one, damaged, inconsistent or too large is a
        :class:`~aptkt.errors.PriorFileError` naming the member."""
        path = Path(path)
        meta, arrays = read_members(path)
        prefixes = {f"a{i}" for i in range(len(meta["actions"]))}
        extra = sorted(k for k in arrays if k.split("/")[0] not in prefixes | {"calibration"})
        if extra:
            raise PriorFileError(f"{path}: member {extra[0]!r} belongs to no action of the file")
        check_calibration(path, arrays, meta)
        actions = {}
        extractions = meta.get("extractions", {})
        joint = meta.get("joint")
        for i, name in enumerate(meta["actions"]):
            p = f"a{i}"
            check_action(path, arrays, p, name)
            if joint is not None and (name in joint) != (f"{p}/pipeline/joint" in arrays):
                raise PriorFileError(
                    f"{path}: member {p}/pipeline/joint (action {name}): "
                    + ("missing" if name in joint else "present")
                    + " where member 'meta' says "
                    + ("the metric whitens across modalities" if name in joint else "it does not")
                )
            try:
                obs = Observations.from_npz(name, arrays, f"{p}/obs")
                obs.extraction = extractions.get(name)
                pipeline = FeaturePipeline.from_state(arrays, f"{p}/pipeline")
                model_state = {
                    k[len(f"{p}/model/") :]: v
                    for k, v in arrays.items()
                    if k.startswith(f"{p}/model/")
                }
                model = LaplaceGPC.from_state(model_state)
            except (ValueError, KeyError, IndexError, TypeError) as exc:
                raise PriorFileError(f"{path}: members {p}/... (action {name}): {exc}") from None
            if list(model.modality_names_) != list(pipeline.modality_names_):
                raise PriorFileError(
                    f"{path}: member {p}/model/meta (action {name}): modalities "
                    f"{model.modality_names_} differ from the pipeline's "
                    f"{list(pipeline.modality_names_)}"
                )
            sample = arrays.get(f"{p}/sample")
            actions[name] = ActionPrior(name, obs, pipeline, model, sample)
            impostors = arrays.get(f"{p}/impostors")
            identity = actions[name].identity
            if impostors is not None and identity is not None:
                try:
                    identity.impostors = impostors
                except InvalidInputError as exc:
                    raise PriorFileError(
                        f"{path}: member {p}/impostors (action {name}): {exc}"
                    ) from None
        library = cls(actions, meta.get("metadata", {}))
        if "calibration/held_in" in arrays:
            from aptkt.learning.recognition import CalibrationScores

            library.calibration_scores = CalibrationScores(
                held_in=arrays["calibration/held_in"],
                held_out=arrays["calibration/held_out"],
                touches=int(meta["calibration_touches"]),
            )
        return library

    def recognise(
        self,
        observations: Mapping[str, Observations] | Observations,
        *,
        false_alarm_rate: float = 0.05,
    ) -> Recognition:
        """Which of the library's objects each touch is, how sure, and whether it is one of
        them at all (:mod:`aptkt.learning.recognition`): ``observations`` of one action, or
        action -> observations (rows of several actions with the same object and trial are one
        touch, their evidence fused). The novelty threshold is chosen on the library itself for
        ``false_alarm_rate`` (computed once per rate). ``pandas.DataFrame(result.rows())`` is
        the table."""
        from aptkt.learning.recognition import recognise, require_identities

        table = (
            {observations.action: observations}
            if isinstance(observations, Observations)
            else dict(observations)
        )
        require_identities(self, [a for a in table if a in self])
        return recognise(self, table, calibration=self.scores().calibration(false_alarm_rate))

    def scores(self, parallel_map: Any = None, progress: Any = None) -> CalibrationScores:
        """The library's calibration scores for recognition
        (:func:`~aptkt.learning.recognition.calibration_scores`), computed once (or read from
        its file)."""
        if self.calibration_scores is None:
            from aptkt.learning.recognition import calibration_scores

            self.calibration_scores = calibration_scores(self, parallel_map, progress)
        return self.calibration_scores

    def precompute_parts(self) -> int:
        """How many parts :meth:`precompute` has left to compute (its progress's total)."""
        from aptkt.learning.recognition import calibration_parts

        parts = sum(
            len(impostor_parts(len(p.objects)))
            for p in self.actions.values()
            if p.identity is not None and p.identity.impostors is None
        )
        return parts + (calibration_parts(self) if self.calibration_scores is None else 0)

    def precompute(self, parallel_map: Any = None, progress: Any = None) -> None:
        """What a saved library carries besides its models, so that learning and recognising
        with it start at once: each action's impostor table (the same-object cut-off's
        threshold, :meth:`~aptkt.learning.identity.ObjectIdentity.impostor_log_odds`) and the
        calibration scores of recognition. Their cost grows with the library (a few seconds
        per thousand objects); ``parallel_map`` (an executor's ``imap_unordered``) spreads it
        over processes or a cluster; ``progress.update(1)`` after each of
        :meth:`precompute_parts` parts."""
        for prior in self.actions.values():
            identity = prior.identity
            if identity is not None and identity.impostors is None:
                identity.impostors = impostor_table(
                    prior._training_X,
                    prior.observations.objects,
                    parallel_map,
                    identity,
                    progress,
                )
        self.scores(parallel_map, progress)

    def summary(self) -> list[dict[str, Any]]:
        """One row per action: objects, observations, modality weights and length-scales, the
        objects and number of observations the kernel was learned on."""
        rows = []
        for name, prior in self.actions.items():
            m = prior.model
            rows.append(
                {
                    "action": name,
                    "objects": prior.objects,
                    "observations": len(prior.observations),
                    "modalities": m.modality_names_,
                    "weights_mean": m.modality_weights_.mean(axis=0).round(3).tolist(),
                    "length_scales_mean": m.length_scales_.mean(axis=0).round(3).tolist(),
                    "log_marginal_likelihood": m.log_marginal_likelihood_.round(2).tolist(),
                    # What the kernel was learned on (every object within the limits of
                    # aptkt.learning.locality, a random sample of them beyond).
                    "kernel_objects": [str(c) for c in m.classes_],
                    "kernel_observations": int(prior.sample_rows.size),
                }
            )
        return rows

    def subset(
        self, objects: Sequence[str], *, gp: GPSettings | None = None, seed: int = 0
    ) -> PriorKnowledge:
        """Prior knowledge rebuilt on a subset of the old objects (refits the models); without
        ``gp``, at the default settings with this prior's own feature scale."""
        table = {name: prior.observations for name, prior in self.actions.items()}
        if gp is None:
            gp = self.gp_settings
        return PriorKnowledge.build(table, objects, gp=gp, seed=seed)

    @property
    def gp_settings(self) -> GPSettings:
        """The settings this prior was built with (files from before the current settings:
        the defaults with the file's own feature scale)."""
        recorded = self.metadata.get("gp")
        try:
            return GPSettings.from_dict(recorded) if isinstance(recorded, dict) else GPSettings()
        except (TypeError, ValueError):
            scale = self.feature_scale
            return GPSettings(prior_feature_scale=scale if scale in FEATURE_SCALES else "whiten")

    @property
    def feature_scale(self) -> str:
        """How this prior's feature space z-scores its columns (``GPSettings.
        prior_feature_scale``); files written before the setting existed used the spread."""
        gp = self.metadata.get("gp")
        return str(gp.get("prior_feature_scale", "spread")) if isinstance(gp, dict) else "spread"
