"""Every parameter of a learning run, recorded with its results."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields, replace
from typing import Any

import numpy as np

from aptkt.gp import (
    CLASS_PRIORS,
    DEFAULTS,
    LATENT_MEANS,
    HyperPrior,
    LaplaceGPC,
    check_optimizer_tol,
)
from aptkt.learning.pipeline import FEATURE_SCALES
from aptkt.learning.transfer import (
    CUTOFFS,
    FEATURE_SPACES,
    RELATEDNESS,
    SOURCE_CHOICES,
    SOURCE_TASKS,
    TRANSFER_MODES,
)

__all__ = ["GPSettings", "LearnerConfig", "WARM_STARTS"]

#: First starts of the hyper-parameter search (``LearnerConfig.warm_start``).
WARM_STARTS = (None, "previous", "source", "both")


@dataclass(frozen=True)
class GPSettings:
    """How the observation models (one-vs-all Laplace GPCs) are fitted.

    n_restarts : random starts of each classifier's hyper-parameter search besides the first
        one at the hyper-prior's centre; 0 by default (see the comment at the field).
    hyper_prior : "weak" (default): MAP-II, the marginal likelihood times weak log-normal
        hyper-priors centred on the data's scale (length-scales) and on σ² = 1, one standard
        deviation a factor of 10 (``aptkt.gp.HyperPrior``). It keeps a classifier that has
        little evidence (one observation of its object, or a block of positives-only source
        rows) from explaining its data by a flat latent function — an extremely long
        length-scale with a huge signal variance — under which λ carries no shape.
        None: plain ML-II, the paper's "maximising the log marginal likelihood".
    modality_weight_prior : with ``hyper_prior="weak"``, whether the modality weights γ get
        their weak prior too (default True: normal logits centred on equal weights). With one
        observation per object the likelihood barely depends on γ, and without it each
        one-vs-all classifier drifts to weights of 10⁻⁶ on one modality or the other, so the
        classifiers of one action model look at different sensors. False: flat weights, the
        reading before this prior existed (its runs and prior files keep their keys).
    class_prior : how the one-vs-all probabilities are combined into the class posterior of
        new observations (decisions, fusion, accuracy). "uniform" (default): each classifier's
        base rate — its share of positive labels, source rows included — is replaced by 1/K
        first (``aptkt.gp.LaplaceGPC``): the active learner, not the world, chose how often each
        object was observed, and every new object is equally likely to be met. "training": as
        fitted, so an object counts as often as the learner happened to observe it (the
        paper's normalised one-vs-all posterior). The selection's uncertainty scores the
        training observations under the frequencies they were drawn with either way. Measured
        both ways in docs/method.md.
    optimizer_tol : the hyper-parameter search stops when an iteration lowers the negative log
        posterior by less than this fraction of it. 1e-6 by default, not scipy's 2.2e-9 (the
        estimator's default): the objective is tens to hundreds of nats, so the search stops
        once an iteration gains less than about 10⁻⁴ nats — far below anything the
        hyper-parameters' posterior can tell apart — and the learning runs need 8–11 % less
        CPU. What further iterations would have found is measured, not bounded: on 87 sampled
        runs of the full-size store 47 curves change, by +0.01 pp on average over the curve
        (docs/method.md, benches/README.md).
    latent_mean : the constant prior mean of each one-vs-all classifier's latent function.
        "zero" (default): the zero-mean GP, as in the paper; far from its data every classifier
        returns to ½. "base-rate": the log-odds of its (smoothed) share of positive labels,
        source rows included (``aptkt.gp.LaplaceGPC``), so that far from its data a classifier
        returns to the rate it was trained at — what the "uniform" class prior's adjustment
        assumes, and what keeps an old object's binary probability (the relatedness of Eq. 3)
        below ½ for observations unlike any of its own. Measured at full size and not made the
        default: it neither lowered the transfer rate with dissimilar priors nor repaired the
        over-correction with many priors, and it cost the auxiliary features with 10 priors
        4 pp at step 1 (docs/method.md).
    prior_feature_scale : how the prior's feature space z-scores each column (the transforms
        fitted on the old objects' observations, in which the old models live and the
        transferring new models are fitted). "noise" (default): by its pooled standard
        deviation within each old object's repeated observations — the variation of the skin
        and the action between observations of one object, a property of the sensor rather
        than of the objects that happen to have been learned before; distances then count how
        many noise levels two observations are apart (the within-class standardisation of
        discriminant analysis). "spread": by its standard deviation over all the old
        observations, which measures how different the chosen old objects are from each other
        (the reading before this setting existed). The new objects' own space (the
        baseline's) always uses the spread: with one observation per object it has no repeated
        observations to estimate the noise from. Measured in docs/method.md.
    """

    # One start, at the hyper-prior's centre (data-scaled length-scales, σ² = 1, equal weights),
    # not the estimator's extra random start: under MAP-II the random start found nothing better
    # at full size and cost a third of the CPU (docs/method.md). With ``hyper_prior=None`` (ML-II,
    # whose flat optima the random start was for) give n_restarts ≥ 1.
    n_restarts: int = 0
    max_iter: int = DEFAULTS.max_iter
    optimizer_tol: float = 1e-6
    length_scale: float | str = DEFAULTS.length_scale
    signal_variance: float = DEFAULTS.signal_variance
    approximation: str = DEFAULTS.approximation
    n_jobs: int | None = DEFAULTS.n_jobs
    # The learner's choice, deliberately not the estimator's default (plain ML-II, as
    # scikit-learn's): see the docstring and docs/method.md.
    hyper_prior: str | None = "weak"
    modality_weight_prior: bool = True
    # The learner's choice, not the estimator's default ("training", as scikit-learn's).
    class_prior: str = "uniform"
    latent_mean: str = DEFAULTS.latent_mean
    # The learner's choice, not the pipeline's default ("spread"): see the docstring.
    prior_feature_scale: str = "noise"
    kernel: str = "per-classifier"
    kernel_data: str = "new"
    modality_weights: str = "fitted"
    signal_variance_centre: float = 1.0

    def __post_init__(self) -> None:
        if self.hyper_prior not in ("weak", None):
            raise ValueError(f"hyper_prior must be 'weak' or None, got {self.hyper_prior!r}")
        if self.class_prior not in CLASS_PRIORS:
            raise ValueError(f"class_prior must be one of {CLASS_PRIORS}, got {self.class_prior!r}")
        if self.latent_mean not in LATENT_MEANS:
            raise ValueError(f"latent_mean must be one of {LATENT_MEANS}, got {self.latent_mean!r}")
        check_optimizer_tol(self.optimizer_tol)
        if self.prior_feature_scale not in FEATURE_SCALES:
            raise ValueError(
                f"prior_feature_scale must be one of {FEATURE_SCALES}, "
                f"got {self.prior_feature_scale!r}"
            )
        if not isinstance(self.modality_weight_prior, bool):
            raise ValueError(
                f"modality_weight_prior must be True or False, got {self.modality_weight_prior!r}"
            )

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        # Left out at "training" (the reading before the setting existed), so that the keys of
        # runs and prior files stored then stay valid (they hash this dict).
        if d["class_prior"] == "training":
            del d["class_prior"]
        if d["latent_mean"] == "zero":  # likewise
            del d["latent_mean"]
        if d["optimizer_tol"] == DEFAULTS.optimizer_tol:  # likewise
            del d["optimizer_tol"]
        if d["prior_feature_scale"] == "spread":  # the reading before the setting: likewise
            del d["prior_feature_scale"]
        # The keys of runs and prior files from before the weight prior describe flat weights:
        # that reading leaves the field out, the new default puts it in (and so gets new keys).
        if self.hyper_prior is None or not self.modality_weight_prior:
            del d["modality_weight_prior"]
        return d

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> GPSettings:
        """The inverse of :meth:`to_dict` (a dict without ``modality_weight_prior`` was written
        with flat weights, one without ``class_prior`` with "training", one without
        ``latent_mean`` with "zero", one without ``optimizer_tol`` with scipy's tolerance, one
        without ``prior_feature_scale`` with "spread")."""
        data = dict(data)
        if data.get("hyper_prior", "weak") is not None:
            data.setdefault("modality_weight_prior", False)
        data.setdefault("class_prior", "training")
        data.setdefault("latent_mean", "zero")
        data.setdefault("optimizer_tol", DEFAULTS.optimizer_tol)
        data.setdefault("prior_feature_scale", "spread")
        return cls(**data)

    def resolved_hyper_prior(self) -> str | HyperPrior | None:
        """The estimator's ``hyper_prior`` for these settings ("weak" by name at the default, so
        that saved models stay readable by versions that know no other field)."""
        if self.hyper_prior is None or self.modality_weight_prior:
            return self.hyper_prior
        return replace(HyperPrior.weak(), modality_weight_sd=None)

    def make(self, modalities: Mapping[str, list[int]], random_state: int) -> LaplaceGPC:
        hp = self.resolved_hyper_prior()
        if hp is not None and self.signal_variance_centre != 1.0:
            hp = replace(HyperPrior.resolve(hp), signal_variance_centre=self.signal_variance_centre)
        fixed = ("transfer_lambda",) if self.modality_weights == "fitted" else ("transfer_lambda", "modality_weights")
        return LaplaceGPC(
            fixed=fixed,
            kernel=self.kernel,
            length_scale=self.length_scale,
            signal_variance=self.signal_variance,
            modalities=dict(modalities),
            n_restarts=self.n_restarts,
            max_iter=self.max_iter,
            optimizer_tol=self.optimizer_tol,
            approximation=self.approximation,
            random_state=random_state,
            n_jobs=self.n_jobs,
            hyper_prior=hp,
            class_prior=self.class_prior,
            latent_mean=self.latent_mean,
        )


@dataclass(frozen=True)
class LearnerConfig:
    """Parameters of APTKT (and of the baseline, which is ``transfer="none"``).

    eps_neg : the cut-off of Eq. 3 below which no prior object is transferred. 0.5 with the
        default binary relatedness: the old object's own classifier must claim the new
        object's observations on average (its decision threshold); far from its data a GP
        classifier's probability returns to 0.5 ("don't know"), which must not pass for
        relatedness. (The normalised relatedness lives on another scale: p̄_max ≥ 1/N_old.)
    eps_explor : probability of a uniformly random (action, object) pick (Eq. 4).
    budget : observations collected by active selection after the initial round (which
        observes every action once on every new object).
    transfer : "paper" (Eq. 2–3: the most related old object per new object), "multi" (every
        old object above ε_neg, each with its own λ, in one multi-source kernel), "none" (the
        paper's baseline: nothing of the prior, feature transforms fitted on the new objects'
        training observations) or "control" (the prior's feature space, no transfer).
    source : the source task handed to the dependent kernel: "one-vs-all" (the chosen old
        object's observations +1, the other old objects' −1) or "positives" (the chosen old
        object's observations only, all +1).
    feature_space : where APTKT's new-object models live. "auto" (default): in the prior's
        feature space (transforms fitted on the many old observations, where old and new
        observations compare) when the update transfers from at least one old object, and in
        the baseline's (fitted on the new objects' training observations) when the cut-off
        stops every transfer — irrelevant prior knowledge is then not used at all, and APTKT
        equals the baseline. "prior": always the prior's; "new": always the baseline's, with
        the old observations mapped into it; "covered": the prior's only when every new
        object transfers (the prior's transforms then come from a population that covers
        them all); "pooled": when the update transfers, transforms fitted on the old and the
        new observations together (the population the dependent kernel compares), the
        baseline's otherwise; "evidence": when the update transfers, the model is fitted in
        both the prior's space and the new objects' own, and the one under which the new
        objects' labels are more probable is kept (Laplace evidence of each one-vs-all
        classifier's labels given its source task, summed over the classifiers; ties and
        failures keep the prior's space), the baseline's when nothing transfers — one more
        fit per transferring update; not with ``transfer="multi"``. "blended" (experimental):
        when the update transfers, transforms fitted on the new training observations (each
        counted once) together with every old object as one more observation (its observations
        share a weight of 1), so that the prior's population informs them while the new
        observations are few and fades as they accumulate. "shrunk" (experimental): the
        same with the old observations weighing κ per modality, chosen by the new
        observations' evidence under a Normal-Gamma prior centred on the old population
        (``pipeline.prior_weight``). The old models always
        judge relatedness (Eq. 3), the evidence cut-off and auxiliary features (Eq. 5) in
        their own space.
    relatedness : p̄ of Eq. 3 from each old object's own binary classifier ("binary", paper
        §4.2) or from the normalised one-vs-all posterior ("normalised").
    cutoff : "evidence" (default, beyond the paper): Eq. 3's ε_neg, and then the new
        objects' own labels must favour the transfer — the log Bayes factor of the dependent
        model (source coupled by λ) against λ = 0, under the old classifier's kernel, must
        exceed ``evidence_margin``. p̄ says which old object the new one is most like among
        the old ones; a one-vs-all classifier of the old objects also claims objects that are
        like none of them, which the evidence test rejects. "paper": Eq. 3 exactly.
        "fitted" (experimental): Eq. 3's ε_neg, then each transfer is kept only if the fitted
        transfer model makes the new object's labels more probable than the same classifier
        fitted without the source (both at their own fitted hyper-parameters); one more fit
        without sources per transferring update, and a refit when a transfer is dropped.
        Only with ``transfer="paper"``.
    evidence_margin : the log Bayes factor a transfer must exceed under ``cutoff="evidence"``.
        0 (default): equal prior odds of "related" and "unrelated" — transfer when the source
        makes the new labels more probable than no source does.
    source_choice, forced_lambda : stress tests of the cut-off only — transfer the "least"
        related old object instead of the "most", and replace λ = p̄ by a fixed value once the
        cut-off has let the transfer through. None: λ = p̄ (the method).
    auxiliary : append the prior models' posteriors as an extra modality (Eq. 5).
    patience : stop early when the mean uncertainty over all pairs has not decreased for this
        many consecutive observations (None: always spend the budget).
    seed : seeds exploration and the GP optimiser starts.
    modalities : use only these modalities in the new objects' models (e.g. ``("force",)`` for a
        single-modality model as in Fig. 6); None: every modality of each action. The prior
        models always see all of theirs.
    warm_start : an experimental first start of each classifier's hyper-parameter search (the
        data-scaled random restarts are kept). None (default): the data-scaled start.
        "previous": the optimum of the same action's and class's previous update (the fit then
        depends on the order of the earlier refits). "source": for a class that transfers,
        the hyper-parameters of the chosen (most related) old object's own classifier. "both":
        "source" where it applies, "previous" elsewhere. Measured in benches/README.md.
    """

    eps_neg: float = 0.5
    eps_explor: float = 0.1
    budget: int = 40
    transfer: str = "paper"
    source: str = "one-vs-all"
    feature_space: str = "auto"
    relatedness: str = "binary"
    cutoff: str = "evidence"
    evidence_margin: float | None = 0.0
    source_choice: str = "most"
    forced_lambda: float | None = None
    auxiliary: bool = False
    patience: int | None = None
    seed: int = 0
    modalities: tuple[str, ...] | None = None
    gp: GPSettings = field(default_factory=GPSettings)
    warm_start: str | None = None

    def __post_init__(self) -> None:
        for name, allowed in (
            ("transfer", TRANSFER_MODES),
            ("source", SOURCE_TASKS),
            ("feature_space", FEATURE_SPACES),
            ("relatedness", RELATEDNESS),
            ("source_choice", SOURCE_CHOICES),
            ("cutoff", CUTOFFS),
        ):
            if getattr(self, name) not in allowed:
                raise ValueError(f"{name} must be one of {allowed}, got {getattr(self, name)!r}")
        if self.cutoff == "fitted" and self.transfer == "multi":
            raise ValueError(
                'cutoff="fitted" judges one source per classifier; use it with transfer="paper"'
            )
        if self.cutoff == "fitted" and self.feature_space in ("covered", "evidence"):
            # "covered" may move the refit to another space than the one the kept transfers
            # were judged in; "evidence" chooses the space by its own evidence comparison.
            raise ValueError(
                f'cutoff="fitted" cannot be combined with feature_space="{self.feature_space}"'
            )
        if (
            self.cutoff == "fitted" or self.feature_space == "evidence"
        ) and self.gp.latent_mean != "zero":
            # Both need the target's own evidence at the coupled model's prior mean, which the
            # base-rate mean takes from the source and target labels together.
            raise ValueError(
                'cutoff="fitted" and feature_space="evidence" need GPSettings(latent_mean="zero")'
            )
        if self.warm_start not in WARM_STARTS:
            raise ValueError(f"warm_start must be one of {WARM_STARTS}, got {self.warm_start!r}")
        if self.feature_space == "evidence" and self.transfer == "multi":
            # With λ = 0 several sources become independent of each other as well, so the
            # evidence of the new labels given the sources has no factorisation to use.
            raise ValueError(
                "feature_space='evidence' needs one source per classifier; "
                "it does not work with transfer='multi'"
            )
        if self.forced_lambda is not None and not 0.0 <= self.forced_lambda <= 1.0:
            raise ValueError(
                f"forced_lambda must be None or lie in [0, 1], got {self.forced_lambda}"
            )
        if self.evidence_margin is not None and not np.isfinite(self.evidence_margin):
            raise ValueError(f"evidence_margin must be None or finite, got {self.evidence_margin}")
        for name in ("eps_neg", "eps_explor"):
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"{name} must lie in [0, 1], got {v}")
        if self.budget < 0:
            raise ValueError(f"budget must be >= 0, got {self.budget}")
        if self.modalities is not None:
            object.__setattr__(self, "modalities", tuple(str(m) for m in self.modalities))
            if not self.modalities:
                raise ValueError("modalities must name at least one modality (or be None)")
        if self.patience is not None and self.patience < 1:
            raise ValueError(f"patience must be None or >= 1, got {self.patience}")

    @property
    def uses_prior(self) -> bool:
        """Whether the run reads the prior knowledge at all (the baseline does not)."""
        return self.transfer != "none" or self.auxiliary

    @property
    def transfers(self) -> bool:
        return self.transfer in ("paper", "multi")

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        # Left out at its default, so that the run keys of results stored before the setting
        # existed stay valid (the key hashes this dict).
        if d["warm_start"] is None:
            del d["warm_start"]
        d["gp"] = self.gp.to_dict()
        return d

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> LearnerConfig:
        data = dict(data)
        gp = GPSettings.from_dict(data.pop("gp", {}))
        known = {f.name for f in fields(cls)}
        unknown = set(data) - known
        if unknown:
            raise ValueError(f"unknown learner setting(s): {sorted(unknown)}")
        return cls(gp=gp, **data)
