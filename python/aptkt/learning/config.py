"""Every parameter of a learning run, recorded with its results."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from aptkt.errors import InvalidInputError
from aptkt.gp.settings import DEFAULTS, HyperPrior, check_optimizer_tol
from aptkt.gp.settings import KERNELS as ESTIMATOR_KERNELS
from aptkt.learning.active import SELECTIONS
from aptkt.learning.pipeline import FEATURE_SCALES
from aptkt.learning.transfer import CUTOFFS, TRANSFER_MODES

if TYPE_CHECKING:
    from aptkt.gp.estimator import LaplaceGPC

__all__ = [
    "GPSettings",
    "KERNELS",
    "LIBRARY_MODELS",
    "LONE_OBSERVATION_POSTERIOR",
    "LearnerConfig",
    "READINGS",
    "lone_observation_signal_variance",
    "recognisable_signal_variance",
]

#: "library": one kernel for every one-vs-all classifier of an action whose amplitude follows
#: from how many new objects compete (:func:`lone_observation_signal_variance`) and whose
#: length-scale the library's observations determine at that amplitude, once per library;
#: then the estimator's own (:data:`aptkt.gp.KERNELS`, defined there only): "shared", one
#: kernel learned on the old and the new objects' observations together, refitted at every
#: update; "per-classifier", each classifier fits its own on its own labels (the paper's
#: reading).
KERNELS = ("library", *ESTIMATOR_KERNELS)
#: The class posterior that one observation of a new object, alone in its region of the feature
#: space, reaches at itself among the new objects (see :func:`lone_observation_signal_variance`).
LONE_OBSERVATION_POSTERIOR = 0.9
#: The method as this package implements it by default, or the paper's exact reading.
READINGS = ("aptkt", "paper")
#: "local": the library's kernel learned on a sample of its objects, each old object's
#: classifier on its neighbourhood (:mod:`aptkt.learning.locality`); "exact": every classifier
#: on every old observation (the paper's one-vs-all model; GPSettings.library_model).
LIBRARY_MODELS = ("local", "exact")


def recognisable_signal_variance(probability: float = 0.95) -> float:
    """The signal variance σ² at which a GP classifier recognises one isolated observation of a
    class with ``probability`` at that observation: the Laplace mode of one +1 label with
    nothing else nearby solves f = σ² (1 − sigmoid(f)), so σ² = logit(p) / (1 − p).

    With σ² = 1 (the usual unit) the best a lone observation can reach is 0.61 — a belief that
    distinct objects cannot be told apart, under which one-vs-all classifiers never saturate:
    their latent function stays a kernel-weighted *sum* over the observations, so the object
    observed once more than the others claims more of the feature space, and accuracy falls
    after the first actively chosen observation (docs/method.md, "Never unlearning")."""
    if not 0.5 < probability < 1.0:
        raise InvalidInputError(f"probability must lie in (0.5, 1), got {probability}")
    return math.log(probability / (1.0 - probability)) / (1.0 - probability)


def lone_observation_signal_variance(
    n_classes: int, posterior: float = LONE_OBSERVATION_POSTERIOR
) -> float:
    """The signal variance σ² at which one observation of a class, alone in its region of the
    feature space, reaches the class posterior ``posterior`` at itself among ``n_classes``
    one-vs-all classifiers: its own classifier gives it p, each of the others 1 − p (the same
    lone label, negative), so the normalised posterior is p / (p + (K − 1)(1 − p)), and σ² is
    :func:`recognisable_signal_variance` of that p.

    The amplitude of the new objects' kernel is a property of the task — how many objects the
    observations must be told from — not of the library, whose evidence favours ever larger
    amplitudes as it grows (its objects, observed many times each, are separable; measured on
    real data: σ² ≈ 500 with 3 old objects, 1,500–2,100 with 15), and a kernel that certain of
    every observation learns little from the next one (docs/method.md). Below σ² ≈ 60 with five
    objects a one-vs-all model unlearns: the object observed once more claims territory."""
    if n_classes < 2:
        raise InvalidInputError(f"n_classes must be >= 2, got {n_classes}")
    if not 0.0 < posterior < 1.0:
        raise InvalidInputError(f"posterior must lie in (0, 1), got {posterior}")
    others = n_classes - 1
    p = posterior * others / (1.0 - posterior + posterior * others)
    return recognisable_signal_variance(p)


@dataclass(frozen=True)
class GPSettings:
    """How the observation models (one-vs-all Laplace GPCs) are fitted.

    kernel : "library" (default): where the new objects' model lives in the prior's feature space
        (APTKT and the control), one kernel with equal modality weights serves every one-vs-all
        classifier of the action; its σ² follows from the number of new objects
        (:func:`lone_observation_signal_variance`), and its one length-scale maximises the new
        classifiers' summed evidence under a hyper-prior centred on the length-scale the
        library's observations favour at that σ² (:mod:`aptkt.learning.kernel`). How
        confident one observation may be depends on how many objects it must be told from,
        which the new task sets; the library knows the sensor's length-scales, and the new
        objects' labels correct it where they lie closer together (docs/method.md).
        "shared": one kernel serves every one-vs-all classifier of the action,
        the old model's included, and is chosen on the old and the new objects' observations
        together (the sum of every classifier's Laplace evidence). In that space every modality
        is measured in the sensor's noise, so the kernel has two hyper-parameters: σ² and one
        length-scale for all modalities, with equal weights. A kernel describes how one
        sensor's observations of one action vary: the old objects, observed many times each,
        determine it where a handful of new observations cannot, and as the new ones accumulate
        they weigh in. Which modality separates objects is a property of the objects, not of
        the sensor, so it is not carried over from the old ones (measured: per-modality
        length-scales or fitted weights chosen on three old objects cost 1.6–3.4 pp at one
        shot on real data; docs/method.md). "per-classifier": each classifier fits its own —
        σ², a length-scale per modality and the weights γ of Eq. 1 — on its own labels (the
        paper's reading). The baseline, which has no prior observations to share a kernel
        with, always fits per classifier.
    hyper_prior : "weak" (default): MAP-II, the evidence times weak log-normal hyper-priors —
        length-scales centred on the data's scale, σ² centred on
        :func:`recognisable_signal_variance` (one isolated observation recognised with
        probability 0.95), each one standard deviation a factor of 10. None: plain ML-II (the
        paper's "maximising the log marginal likelihood").
    prior_feature_scale : the metric of the prior's feature space, where the old models live and
        the new objects' models are fitted (``pipeline.FEATURE_SCALES``). "whiten-joint"
        (default): as "whiten", then the noise correlations between modalities removed as well
        (shrunk by ``pipeline.CROSS_MODAL_SHRINKAGE`` first), so that noise one contact puts
        into several modalities counts once. "whiten":
        each modality whitened by the old objects' pooled within-object covariance — distances
        count the sensor's noise levels, correlated noise counted once (the Mahalanobis metric
        of discriminant analysis): a property of the sensor and the action that carries over to
        new objects whether or not they resemble the old ones. "spread": each column z-scored
        over the old observations (the paper's reading: the features are normalised). The
        baseline's space is always the new objects' own spread: it uses nothing of the prior.
    library_model : how the library's one-vs-all model of its old objects is fitted. "local"
        (default): its kernel on a random sample of the old objects, and each old object's
        classifier on its neighbourhood — itself and the objects nearest to it — within the
        limits of :mod:`aptkt.learning.locality` (16 objects, 400 observations); a new object is
        compared (Eq. 3) with the old objects most likely to have given its observations. Its
        cost does not grow with the library, and a library within the limits is fitted exactly
        as with "exact". "exact": every classifier on every old observation (the paper's one-
        vs-all model; its cost grows as N⁴ with N old objects: a library of 100 objects takes
        minutes and 5 GB).
    n_restarts : random starts of the hyper-parameter search besides the one at the hyper-prior's
        centre (0 by default: under MAP-II the random start found nothing better and cost a
        third of the CPU; with ``hyper_prior=None`` give n_restarts ≥ 1).
    optimizer_tol : the search stops when an iteration lowers the negative log posterior by less
        than this fraction of it (1e-6: about 10⁻⁴ nats here, far below what the posterior of
        the hyper-parameters can tell apart).
    """

    n_restarts: int = 0
    max_iter: int = DEFAULTS.max_iter
    optimizer_tol: float = 1e-6
    length_scale: float | str = DEFAULTS.length_scale
    signal_variance: float = DEFAULTS.signal_variance
    approximation: str = DEFAULTS.approximation
    n_jobs: int | None = DEFAULTS.n_jobs
    hyper_prior: str | None = "weak"
    kernel: str = "library"
    prior_feature_scale: str = "whiten-joint"
    library_model: str = "local"

    def __post_init__(self) -> None:
        if self.hyper_prior not in ("weak", None):
            raise InvalidInputError(f"hyper_prior must be 'weak' or None, got {self.hyper_prior!r}")
        for name, allowed in (
            ("kernel", KERNELS),
            ("prior_feature_scale", FEATURE_SCALES),
            ("library_model", LIBRARY_MODELS),
        ):
            if getattr(self, name) not in allowed:
                raise InvalidInputError(
                    f"{name} must be one of {allowed}, got {getattr(self, name)!r}"
                )
        check_optimizer_tol(self.optimizer_tol)

    @classmethod
    def paper(cls, **changes: Any) -> GPSettings:
        """The paper's reading: per-classifier ML-II (one random restart against ML-II's flat
        optima) in a feature space z-scored by the old objects' spread."""
        base = cls(
            n_restarts=1,
            hyper_prior=None,
            kernel="per-classifier",
            prior_feature_scale="spread",
            library_model="exact",
        )
        return replace(base, **changes)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> GPSettings:
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise InvalidInputError(
                f"unknown GP setting(s) {unknown}: written by another version of aptkt"
            )
        return cls(**data)

    def hyper_prior_for_fit(self, shared: bool = False) -> HyperPrior | None:
        """The estimator's hyper-prior for these settings (the weights' prior only where they
        are fitted, i.e. not in the shared kernel)."""
        if self.hyper_prior is None:
            return None
        weak = HyperPrior.weak()
        return replace(
            weak,
            signal_variance_centre=recognisable_signal_variance(),
            modality_weight_sd=None if shared else weak.modality_weight_sd,
        )

    def make(
        self, modalities: Mapping[str, list[int]], random_state: int, *, shared: bool = False
    ) -> LaplaceGPC:
        """An unfitted model; ``shared``: the shared kernel (equal weights, one length-scale),
        for its classifiers and its kernel tasks."""
        # Here, not at the top: the command line reads these settings without scikit-learn.
        from aptkt.gp.estimator import LaplaceGPC

        return LaplaceGPC(
            length_scale=self.length_scale,
            signal_variance=self.signal_variance,
            modalities=dict(modalities),
            n_restarts=self.n_restarts,
            max_iter=self.max_iter,
            optimizer_tol=self.optimizer_tol,
            approximation=self.approximation,
            random_state=random_state,
            n_jobs=self.n_jobs,
            hyper_prior=self.hyper_prior_for_fit(shared),
            fixed=("transfer_lambda", "modality_weights") if shared else ("transfer_lambda",),
            kernel="shared" if shared else "per-classifier",
            tie_length_scales=shared,
        )


#: Each selection rule's own ε_explor (:attr:`LearnerConfig.exploration`).
EXPLORATION = {"paper": 0.1, "error-reduction": 0.0, "random": 1.0}


@dataclass(frozen=True)
class LearnerConfig:
    """Parameters of APTKT (and of the baseline, which is ``transfer="none"``).

    transfer : "paper" (Eq. 2–3: the most related old object per new object, through the
        dependent kernel), "none" (the baseline: nothing of the prior — the new objects' own
        feature space, each classifier its own kernel) or "control" (the prior's feature space
        and kernel, no transfer: APTKT and the control differ by the transfer alone).
    eps_neg : Eq. 3's cut-off: no transfer when the most related old object's own classifier
        claims the new object's observations with mean probability below it. 0.5: its decision
        threshold; far from its data a classifier's probability returns to 0.5 ("don't know").
    cutoff : "same-object" (default, beyond the paper): after Eq. 3's ε_neg, the library's
        generative model of its objects (:class:`~aptkt.learning.identity.ObjectIdentity`) must
        hold the new object's observations to be the chosen old object's — against every other
        old object and against an object the library does not hold — with log posterior odds
        above ``evidence_margin``. "evidence": instead, the log Bayes factor of the dependent
        model (source coupled by λ) against λ = 0, under the new objects' kernel, must exceed
        ``evidence_margin``. "paper": Eq. 3 alone.
    evidence_margin : the log odds a transfer must exceed; 3 by default, "strong evidence" on
        Kass and Raftery's scale. A transfer makes the old object's observations count as the
        new object's — its whole region of the feature space moves to the new object — so a
        wrong transfer costs more than a missed one: on real materials, which are all distinct,
        the transfers a weaker test let through lowered accuracy against the control
        (docs/method.md).
    selection : how the next (action, object) pair is chosen
        (:data:`~aptkt.learning.active.SELECTIONS`): "error-reduction" (default, beyond the
        paper: the pair whose next touch is expected to remove the most error), "paper"
        (AT-LPP, Eq. 4: the pair whose observations so far are most uncertain) or "random"
        (uniformly random picks, the reference).
    eps_explor : probability of a uniformly random (action, object) pick instead of the
        rule's (Eq. 4). None: the rule's own (:data:`EXPLORATION`) — the paper's 0.1 for
        AT-LPP, whose most uncertain pair can stay the most uncertain however often it is
        touched; none for error reduction, whose score of a pair falls with every touch of it,
        so that no pair is starved.
    budget : observations chosen actively after the initial round (every action once on every
        new object).
    auxiliary : append the prior models' posteriors as an extra modality (Eq. 5).
    aux_gate_margin : with ``auxiliary``, the log Bayes factor by which the new labels' Laplace
        evidence must favour the model with the auxiliary features over the model without
        them for the features to be kept at an update; 3 by default (the transfer's
        ``evidence_margin``, on the same scale). An extra modality that the labels do not ask
        for only dilutes the kernel (measured: −1.4 pp at one observation per object on real
        data, docs/method.md). None: no gate, the features are always used (the paper's
        reading, :meth:`paper`: Eq. 5 has no such test). Independent of ``evidence_margin``.
    patience : stop early when the mean uncertainty over all pairs has not fallen for this many
        consecutive observations (None: always spend the budget).
    target_accuracy : stop early once the learner's own estimate of its mean accuracy
        (:class:`~aptkt.learning.estimate.AccuracyEstimate`: every touch judged before it is
        learned) reaches it (None: no such stop).
    seed : seeds the pool order's use, the exploration and the GP optimiser's starts.
    modalities : only these modalities in the new objects' models (Fig. 6's single-modality
        models); None: every modality of each action. The prior models see all of theirs.
    """

    transfer: str = "paper"
    eps_neg: float = 0.5
    cutoff: str = "same-object"
    evidence_margin: float = 3.0
    selection: str = "error-reduction"
    eps_explor: float | None = None
    budget: int = 40
    auxiliary: bool = False
    aux_gate_margin: float | None = 3.0
    patience: int | None = None
    target_accuracy: float | None = None
    seed: int = 0
    modalities: tuple[str, ...] | None = None
    gp: GPSettings = field(default_factory=GPSettings)

    def __post_init__(self) -> None:
        for name, allowed in (
            ("transfer", TRANSFER_MODES),
            ("cutoff", CUTOFFS),
            ("selection", SELECTIONS),
        ):
            if getattr(self, name) not in allowed:
                raise InvalidInputError(
                    f"{name} must be one of {allowed}, got {getattr(self, name)!r}"
                )
        if not np.isfinite(self.evidence_margin):
            raise InvalidInputError(f"evidence_margin must be finite, got {self.evidence_margin}")
        if self.aux_gate_margin is not None and not np.isfinite(self.aux_gate_margin):
            raise InvalidInputError(
                f"aux_gate_margin must be finite or None, got {self.aux_gate_margin}"
            )
        for name in ("eps_neg", "eps_explor"):
            v = getattr(self, name)
            if v is None and name == "eps_explor":
                continue
            if not 0.0 <= v <= 1.0:
                raise InvalidInputError(f"{name} must lie in [0, 1], got {v}")
        if self.budget < 0:
            raise InvalidInputError(f"budget must be >= 0, got {self.budget}")
        if self.modalities is not None:
            object.__setattr__(self, "modalities", tuple(str(m) for m in self.modalities))
            if not self.modalities:
                raise InvalidInputError("modalities must name at least one modality (or be None)")
        if self.patience is not None and self.patience < 1:
            raise InvalidInputError(f"patience must be None or >= 1, got {self.patience}")
        if self.target_accuracy is not None and not 0.0 < self.target_accuracy <= 1.0:
            raise InvalidInputError(
                f"target_accuracy must lie in (0, 1], got {self.target_accuracy}"
            )

    @classmethod
    def paper(cls, **changes: Any) -> LearnerConfig:
        """The paper's exact reading: Eq. 3's cut-off alone, auxiliary features (when asked
        for) without a gate, AT-LPP's selection (Eq. 4), and :meth:`GPSettings.paper`."""
        base = cls(cutoff="paper", aux_gate_margin=None, selection="paper", gp=GPSettings.paper())
        return replace(base, **changes)

    def _transfer_pick(self) -> tuple[str, float | None]:
        """Which related old object a transfer takes ("most": Eq. 2) and its λ (None: p̄).
        Only the reproduction's stress test of the cut-off picks otherwise
        (:mod:`aptkt.experiments.stress`)."""
        return "most", None

    @property
    def exploration(self) -> float:
        """The probability of a uniformly random pick: ``eps_explor``, or the rule's own."""
        if self.selection == "random":
            return 1.0
        return EXPLORATION[self.selection] if self.eps_explor is None else float(self.eps_explor)

    @property
    def uses_prior(self) -> bool:
        """Whether the run reads the prior knowledge at all (the baseline does not)."""
        return self.transfer != "none" or self.auxiliary

    @property
    def transfers(self) -> bool:
        return self.transfer == "paper"

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["gp"] = self.gp.to_dict()
        return d

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> LearnerConfig:
        data = dict(data)
        gp = GPSettings.from_dict(data.pop("gp", {}))
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise InvalidInputError(
                f"unknown learner setting(s) {unknown}: written by another version of aptkt"
            )
        return cls(gp=gp, **data)
