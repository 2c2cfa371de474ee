"""What defines a fit besides the data: the defaults every layer above reads, the weak
hyper-priors (MAP-II), the checks of an estimator's parameters, and the settings object the
compiled core receives."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from aptkt import _core
from aptkt.errors import InvalidInputError, InvalidTypeError
from aptkt.gp.arguments import count, normalise_modalities, real, seed_of, threads

__all__ = [
    "CLASS_PRIORS",
    "KERNELS",
    "DEFAULTS",
    "FitDefaults",
    "HyperPrior",
    "LATENT_MEANS",
    "MAX_ITERATIONS",
    "MAX_RESTARTS",
    "check_class_prior",
    "check_optimizer_tol",
    "core_settings",
    "fit_spec",
]


@dataclass(frozen=True)
class FitDefaults:
    """Default fit settings: the one source of LaplaceGPC's defaults and of the learner's
    ``GPSettings`` (which imports them from here; the GP layer sits below learning)."""

    length_scale: str = "auto"
    signal_variance: float = 1.0
    n_restarts: int = 1
    max_iter: int = 100
    # scipy's L-BFGS-B default (factr 1e7 times machine epsilon), which scikit-learn's GPC uses.
    optimizer_tol: float = 1e7 * float(np.finfo(np.float64).eps)
    approximation: str = "erf"
    n_jobs: int | None = None
    hyper_prior: str | None = None
    class_prior: str = "training"
    latent_mean: str = "zero"
    kernel: str = "per-classifier"
    tie_length_scales: bool = False


DEFAULTS = FitDefaults()
CLASS_PRIORS = ("training", "uniform")
#: "per-classifier": each one-vs-all classifier fits its own kernel hyper-parameters (as
#: scikit-learn's one-vs-rest GPC); "shared": one kernel for every classifier of the model.
KERNELS = ("per-classifier", "shared")
LATENT_MEANS = ("zero", "base-rate")
#: Optimiser starts a fit may add to the first (``n_restarts``): each is a whole optimisation
#: (the defaults make one more), and the starts are held in memory together. The core refuses
#: more too (its own constant, which this one must equal: tests/gp/test_hardening.py).
MAX_RESTARTS = 1000
#: Iterations of the optimiser (``max_iter``) and of the search for the mode
#: (``newton_max_iter``).
MAX_ITERATIONS = 1_000_000

_FIXABLE = ("signal_variance", "length_scale", "modality_weights", "transfer_lambda")
_APPROXIMATIONS = ("erf", "quadrature")
#: Width of the "weak" hyper-prior: one standard deviation of ln ℓ or ln σ² is a factor of 10.
_WEAK_SD = float(np.log(10.0))
#: The same width for the ratio of two modality weights: the logits η_m (γ = softmax(η)) are
#: independent N(0, s²), so ln(γ_a / γ_b) = η_a − η_b has standard deviation √2 s = ln 10.
_WEAK_WEIGHT_SD = _WEAK_SD / float(np.sqrt(2.0))


@dataclass(frozen=True)
class HyperPrior:
    """Weak hyper-priors for MAP-II fitting: log-normal densities on the hyper-parameters.

    Each modality's length-scale ℓ_m gets ``ln ℓ_m ~ N(ln(length_scale_centre · s_m),
    length_scale_sd²)``, where ``s_m`` is that modality's data scale (the median pairwise
    distance of the new observations); the signal variance gets ``ln σ² ~
    N(ln signal_variance_centre, signal_variance_sd²)``. The optimiser then maximises
    ``log p(y | θ) + log p(θ)`` instead of ``log p(y | θ)``; the reported
    ``log_marginal_likelihood_`` stays ``log p(y | θ)``. With several modalities, each
    modality-weight logit η_m (γ = softmax(η)) gets ``η_m ~ N(0, modality_weight_sd²)``:
    centred on equal weights, so that a classifier with too few observations to tell the
    modalities apart does not switch one off (its flat likelihood lets the optimiser drift to
    weights of 10⁻⁶); it also fixes the softmax's redundant direction. A width of None leaves
    that hyper-parameter flat. ``HyperPrior.weak()`` (``hyper_prior="weak"``): centred on the
    data scale, σ² = 1 and equal weights, one standard deviation a factor of 10 either way (of
    ℓ_m, of σ², and of the ratio of two weights).
    """

    length_scale_centre: float = 1.0
    length_scale_sd: float | None = _WEAK_SD
    signal_variance_centre: float = 1.0
    signal_variance_sd: float | None = _WEAK_SD
    modality_weight_sd: float | None = _WEAK_WEIGHT_SD

    def __post_init__(self) -> None:
        for name in ("length_scale_centre", "signal_variance_centre"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float, np.floating)) and np.isfinite(v) and v > 0):
                raise InvalidInputError(f"HyperPrior.{name} must be a finite number > 0, got {v!r}")
        for name in ("length_scale_sd", "signal_variance_sd", "modality_weight_sd"):
            v = getattr(self, name)
            if v is not None and not (
                isinstance(v, (int, float, np.floating)) and np.isfinite(v) and v > 0
            ):
                raise InvalidInputError(
                    f"HyperPrior.{name} must be None or a finite number > 0, got {v!r}"
                )

    @classmethod
    def weak(cls) -> HyperPrior:
        return cls()

    @classmethod
    def resolve(cls, value: Any) -> HyperPrior | None:
        """None, "weak" or a HyperPrior (or its fields as a mapping) to a HyperPrior or None."""
        if value is None or isinstance(value, HyperPrior):
            return value
        if isinstance(value, str):
            if value == "weak":
                return cls.weak()
            raise InvalidInputError(
                f"hyper_prior must be None, 'weak' or a HyperPrior, got {value!r}"
            )
        if isinstance(value, Mapping):
            return cls(**value)
        raise InvalidTypeError(
            f"hyper_prior must be None, 'weak' or a HyperPrior, got {type(value).__name__}"
        )

    def core(self) -> _core.HyperPriors:
        """The priors as the compiled core takes them."""
        return _core.HyperPriors(
            signal_variance=None
            if self.signal_variance_sd is None
            else (float(self.signal_variance_centre), float(self.signal_variance_sd)),
            length_scale=None
            if self.length_scale_sd is None
            else (float(self.length_scale_centre), float(self.length_scale_sd)),
            weight_logit=None
            if self.modality_weight_sd is None
            else float(self.modality_weight_sd),
        )


def check_optimizer_tol(value: Any) -> None:
    """The optimiser's relative tolerance must be a finite real number >= 0 (not a bool)."""
    real(value, "optimizer_tol")


def check_class_prior(*values: str | None) -> None:
    """Each given class prior (None: not given) must be one of :data:`CLASS_PRIORS`."""
    for value in values:
        if value is not None and value not in CLASS_PRIORS:
            raise InvalidInputError(f"class_prior must be one of {CLASS_PRIORS}, got {value!r}")


def fit_spec(est: Any, n_features: int) -> dict[str, Any]:
    """A LaplaceGPC's parameters, checked, for data with ``n_features`` columns."""
    names, groups = normalise_modalities(
        est.modalities, n_features, getattr(est, "feature_names_in_", None)
    )
    m = len(groups)
    if isinstance(est.length_scale, str):
        if est.length_scale != "auto":
            raise InvalidInputError(
                f"length_scale must be a number, a sequence or 'auto', got {est.length_scale!r}"
            )
        length_scales = [float("nan")] * m
    else:
        ls = np.atleast_1d(np.asarray(est.length_scale, dtype=np.float64))
        if ls.size == 1:
            ls = np.repeat(ls, m)
        if ls.size != m:
            raise InvalidInputError(f"length_scale has {ls.size} values for {m} modalities")
        if not np.all(np.isfinite(ls) & (ls > 0)):
            raise InvalidInputError(
                f"length_scale must be 'auto' or finite numbers > 0, got {est.length_scale!r}"
            )
        length_scales = [float(v) for v in ls]
    if est.modality_weights is None:
        weights = [1.0 / m] * m
    else:
        weights = [real(w, "modality_weights") for w in est.modality_weights]
        if len(weights) != m:
            raise InvalidInputError(
                f"modality_weights has {len(weights)} values for {m} modalities"
            )
        if sum(weights) <= 0:
            raise InvalidInputError(f"modality_weights must have a positive sum, got {weights}")
    fixed = set(est.fixed)
    unknown = fixed - set(_FIXABLE)
    if unknown:
        raise InvalidInputError(
            f"fixed: unknown hyper-parameter(s) {sorted(unknown)}; choose from {list(_FIXABLE)}"
        )
    check_class_prior(est.class_prior)
    if est.kernel not in KERNELS:
        raise InvalidInputError(f"kernel must be one of {KERNELS}, got {est.kernel!r}")
    if est.latent_mean not in LATENT_MEANS:
        raise InvalidInputError(
            f"latent_mean must be one of {LATENT_MEANS}, got {est.latent_mean!r}"
        )
    if est.approximation not in _APPROXIMATIONS:
        raise InvalidInputError(
            f"approximation must be one of {_APPROXIMATIONS}, got {est.approximation!r}"
        )
    # Every number is checked here, before the core sees it: NaN, infinity or a bool would
    # otherwise pass as a tolerance or a count and surface as a fit that never ends.
    check_optimizer_tol(est.optimizer_tol)
    real(est.newton_tol, "newton_tol")
    real(est.max_jitter, "max_jitter")
    count(est.n_restarts, "n_restarts", MAX_RESTARTS)
    count(est.max_iter, "max_iter", MAX_ITERATIONS)
    count(est.newton_max_iter, "newton_max_iter", MAX_ITERATIONS)
    threads(est.n_jobs)  # checks the value
    bounds = {}
    for name in ("signal_variance_bounds", "length_scale_bounds"):
        value = getattr(est, name)
        if isinstance(value, (str, bytes)) or np.ndim(value) != 1 or len(value) != 2:
            raise InvalidInputError(f"{name} must be a pair (low, high), got {value!r}")
        lo, hi = (real(v, name, positive=True) for v in value)
        if not lo < hi:
            raise InvalidInputError(f"{name} must satisfy low < high, got {value!r}")
        bounds[name] = (lo, hi)
    return {
        "modality_names": names,
        "modalities": groups,
        "signal_variance": real(est.signal_variance, "signal_variance", positive=True),
        "length_scales": length_scales,
        "weights": weights,
        "free": {k: k not in fixed for k in _FIXABLE},
        "signal_variance_bounds": bounds["signal_variance_bounds"],
        "length_scale_bounds": bounds["length_scale_bounds"],
        "hyper_prior": HyperPrior.resolve(est.hyper_prior),
    }


def core_settings(est: Any, spec: dict[str, Any]) -> _core.FitSettings:
    """The binding's settings object for this estimator's parameters."""
    free = spec["free"]
    prior = spec["hyper_prior"]
    return _core.FitSettings(
        start=_core.KernelStart(
            modalities=spec["modalities"],
            signal_variance=spec["signal_variance"],
            length_scales=spec["length_scales"],
            weights=spec["weights"],
        ),
        free=_core.FreeHyperparameters(
            signal_variance=free["signal_variance"],
            length_scales=free["length_scale"],
            weights=free["modality_weights"],
            transfer_lambda=free["transfer_lambda"],
            tie_length_scales=bool(est.tie_length_scales),
        ),
        search=_core.Search(
            **_typed(est, optimize=bool, n_restarts=int, max_iter=int, optimizer_tol=float),
            seed=seed_of(est.random_state),
            signal_variance_bounds=spec["signal_variance_bounds"],
            length_scale_bounds=spec["length_scale_bounds"],
        ),
        laplace=_core.Laplace(
            **_typed(est, newton_max_iter=int, newton_tol=float, max_jitter=float),
            approximation=est.approximation,
            latent_mean=est.latent_mean,
        ),
        n_threads=threads(est.n_jobs),
        hyper_prior=None if prior is None else prior.core(),
    )


def _typed(est: Any, **types: type) -> dict[str, Any]:
    """The estimator's parameters of these names as the given types (numpy scalars and other
    numbers a user may pass become plain ones)."""
    return {name: kind(getattr(est, name)) for name, kind in types.items()}
