"""Gaussian-process classification with the Laplace approximation (Rust core).

:class:`LaplaceGPC` is a one-vs-all multi-class classifier with the logistic likelihood
(Rasmussen & Williams, Algorithms 3.1, 3.2, 5.1) and the kernels of the APTKT method:

* **multi-modal** (paper Eq. 1): the feature columns are grouped into modalities; each gets an
  RBF kernel with its own length-scale and the kernels are combined as ``Σ γ_m K_m`` with the
  weights ``γ`` on the simplex, times a signal variance;
* **transfer** (paper Eq. 2): a class's binary classifier can be given *source tasks*
  (:class:`TransferSource`), each the observations of a related prior object with their labels
  (positives only, or that object's one-vs-all task), coupled to the new data by the dependent
  kernel ``K = B ⊗ k`` with ``B_ts = λ_s`` (one source: ``[[K_ss, λ K_st], [λ K_ts, K_tt]]``).

Hyper-parameters are found by maximising each classifier's Laplace log marginal likelihood
(ML-II), or that plus a weak log hyper-prior (MAP-II, :class:`HyperPrior`), with analytic
gradients from several starts. The classifiers are fitted in parallel in Rust with the
GIL released. Models are saved with :meth:`LaplaceGPC.save` to a NumPy ``.npz`` file (no pickle).
"""

from __future__ import annotations

import json
import os
import zipfile
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.special import expit, logit
from sklearn.base import BaseEstimator, ClassifierMixin
from sklearn.exceptions import NotFittedError as _SklearnNotFitted
from sklearn.utils.multiclass import check_classification_targets
from sklearn.utils.validation import validate_data

from aptkt import _core
from aptkt.errors import KernelNotPositiveDefiniteError, NotFittedError

__all__ = [
    "CLASS_PRIORS",
    "DEFAULTS",
    "FitDefaults",
    "HyperPrior",
    "KernelNotPositiveDefiniteError",
    "LATENT_MEANS",
    "LaplaceGPC",
    "MAX_ITERATIONS",
    "MAX_RESTARTS",
    "TransferSource",
    "check_optimizer_tol",
    "kernel_matrix",
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


DEFAULTS = FitDefaults()
CLASS_PRIORS = ("training", "uniform")
#: Optimiser starts a fit may add to the first (``n_restarts``): each is a whole optimisation
#: (the defaults make one more), and the starts are held in memory together.
MAX_RESTARTS = 1000
#: Iterations of the optimiser (``max_iter``) and of the search for the mode
#: (``newton_max_iter``).
MAX_ITERATIONS = 1_000_000
LATENT_MEANS = ("zero", "base-rate")

#: Parameters a saved model leaves out at their default (added after the format was fixed).
_OMITTED_AT_DEFAULT = ("class_prior", "latent_mean", "optimizer_tol")
_FIXABLE = ("signal_variance", "length_scale", "modality_weights", "transfer_lambda")
_APPROXIMATIONS = ("erf", "quadrature")
_SAVE_FORMAT = "aptkt.LaplaceGPC/2"
#: Formats :meth:`LaplaceGPC.from_state` still reads (version 1: one positives-only source per
#: class, no hyper-prior).
_OLD_FORMATS = ("aptkt.LaplaceGPC/1",)
#: Width of the "weak" hyper-prior: one standard deviation of ln ℓ or ln σ² is a factor of 10.
_WEAK_SD = float(np.log(10.0))
#: The same width for the ratio of two modality weights: the logits η_m (γ = softmax(η)) are
#: independent N(0, s²), so ln(γ_a / γ_b) = η_a − η_b has standard deviation √2 s = ln 10.
_WEAK_WEIGHT_SD = _WEAK_SD / float(np.sqrt(2.0))


class TransferSource:
    """A source task (a prior object) transferred into one class's binary classifier.

    Parameters
    ----------
    X : array (n_source, n_features)
        The source task's observations, in the target's feature space.
    y : None or array (n_source,)
        Their labels for this binary task. None: positives only (every row +1, the old object's
        own observations). Otherwise the source object's one-vs-all task: +1 for its own
        observations, -1 for the other old objects' (values in {+1, -1}, or booleans / {0, 1}
        with 1 = positive).
    transfer_lambda : float in [0, 1], optional
        Relatedness λ_s of this source to the target task: the kernel between its rows and the
        new observations is scaled by λ_s. Required when λ is fixed (the default); a starting
        value (0.5 if None) when λ is learned.
    name : str, optional
        Names this source in ``hyperparameters_`` (default ``source<k>``).
    """

    __slots__ = ("X", "name", "transfer_lambda", "y")

    def __init__(
        self,
        X: Any,
        y: Any = None,
        transfer_lambda: float | None = None,
        *,
        name: str | None = None,
    ) -> None:
        if y is not None and np.ndim(y) == 0:
            raise TypeError(
                "TransferSource(X, y, transfer_lambda): y must be an array of labels or None, "
                f"got the scalar {y!r}; pass the relatedness as transfer_lambda=..."
            )
        X = _as_matrix(X, "TransferSource.X")
        self.X = X
        self.y = None if y is None else _binary_labels(y, X.shape[0])
        if transfer_lambda is not None:
            lam = float(transfer_lambda)
            if not 0.0 <= lam <= 1.0:  # also rejects NaN
                raise ValueError(f"transfer_lambda must lie in [0, 1], got {transfer_lambda!r}")
            transfer_lambda = lam
        self.transfer_lambda = transfer_lambda
        self.name = None if name is None else str(name)

    @property
    def labels(self) -> np.ndarray:
        """The ±1 labels this source enters its binary classifier with."""
        return np.ones(self.X.shape[0]) if self.y is None else self.y

    def __repr__(self) -> str:
        kind = "positives" if self.y is None else f"{int((self.y > 0).sum())} positives"
        return (
            f"TransferSource({self.X.shape[0]} rows, {kind}, "
            f"transfer_lambda={self.transfer_lambda!r}, name={self.name!r})"
        )


def _binary_labels(y: Any, n: int) -> np.ndarray:
    """±1 float labels from {+1, -1}, {1, 0} or booleans, checked for length and finiteness."""
    arr = np.asarray(y)
    if arr.ndim != 1 or arr.shape[0] != n:
        raise ValueError(
            f"TransferSource.y must have one label per row of X ({n}), got shape {arr.shape}"
        )
    if arr.dtype.kind == "b":
        return np.where(arr, 1.0, -1.0)
    if arr.dtype.kind not in "iuf":
        raise TypeError(f"TransferSource.y must hold numbers or booleans, got dtype {arr.dtype}")
    values = arr.astype(np.float64)
    if not np.all(np.isfinite(values)):
        raise ValueError("TransferSource.y contains a non-finite value")
    positive = values == 1.0
    if np.all(positive | (values == -1.0)):
        return values
    if np.all(positive | (values == 0.0)):
        return np.where(positive, 1.0, -1.0)
    raise ValueError(
        "TransferSource.y must be binary (+1/-1, 1/0 or booleans), got values "
        f"{sorted(set(np.unique(values).tolist()))}"
    )


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
                raise ValueError(f"HyperPrior.{name} must be a finite number > 0, got {v!r}")
        for name in ("length_scale_sd", "signal_variance_sd", "modality_weight_sd"):
            v = getattr(self, name)
            if v is not None and not (
                isinstance(v, (int, float, np.floating)) and np.isfinite(v) and v > 0
            ):
                raise ValueError(
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
            raise ValueError(f"hyper_prior must be None, 'weak' or a HyperPrior, got {value!r}")
        if isinstance(value, Mapping):
            return cls(**value)
        raise TypeError(
            f"hyper_prior must be None, 'weak' or a HyperPrior, got {type(value).__name__}"
        )

    def settings(self) -> dict[str, tuple[float, float] | float | None]:
        """The binding's fields."""
        return {
            "prior_signal_variance": None
            if self.signal_variance_sd is None
            else (float(self.signal_variance_centre), float(self.signal_variance_sd)),
            "prior_length_scale": None
            if self.length_scale_sd is None
            else (float(self.length_scale_centre), float(self.length_scale_sd)),
            "prior_weight_logit": None
            if self.modality_weight_sd is None
            else float(self.modality_weight_sd),
        }


def _as_matrix(X: Any, name: str, n_features: int | None = None) -> np.ndarray:
    arr = np.asarray(X)
    if arr.dtype.kind not in "biuf":
        raise TypeError(f"{name} must hold real numbers, got dtype {arr.dtype}")
    if arr.ndim != 2:
        raise ValueError(
            f"{name} must be a 2-D array (n_samples, n_features), got shape {arr.shape}"
        )
    if arr.shape[0] == 0:
        raise ValueError(f"{name} has no rows")
    if n_features is not None and arr.shape[1] != n_features:
        raise ValueError(f"{name} has {arr.shape[1]} features, expected {n_features}")
    return np.ascontiguousarray(arr, dtype=np.float64)


def _normalise_modalities(modalities: Any, n_features: int) -> tuple[list[str], list[list[int]]]:
    if modalities is None:
        return ["all"], [list(range(n_features))]
    if isinstance(modalities, Mapping):
        items = list(modalities.items())
    else:
        items = [(f"m{i}", cols) for i, cols in enumerate(modalities)]
    if not items:
        raise ValueError("modalities must name at least one group of feature columns")
    names, groups = [], []
    for name, cols in items:
        if isinstance(cols, slice):
            cols = range(n_features)[cols]
        idx = [int(c) for c in np.atleast_1d(np.asarray(cols, dtype=np.int64))]
        bad = [c for c in idx if not 0 <= c < n_features]
        if not idx or bad:
            raise ValueError(
                f"modality {name!r} must list feature columns in [0, {n_features}), got {list(cols)}"
            )
        names.append(str(name))
        groups.append(idx)
    return names, groups


_HYPER_KEYS = ("signal_variance", "length_scales", "modality_weights", "transfer_lambda")


def _positive(value: Any, what: str) -> float:
    v = float(value)
    if not (np.isfinite(v) and v > 0):
        raise ValueError(f"{what} must be a finite number > 0, got {value!r}")
    return v


def _per_modality(values: Any, names: list[str], what: str, partial: bool = False) -> list[float]:
    """Values by modality name (a mapping), or a sequence in modality order, or one scalar.
    ``partial``: a mapping may leave modalities out (NaN for them)."""
    if isinstance(values, Mapping):
        missing = [n for n in names if n not in values]
        extra = [k for k in values if k not in names]
        if (missing and not partial) or extra:
            raise ValueError(f"{what} must name the modalities {names}, got {list(values)}")
        return [float(values[n]) if n in values else float("nan") for n in names]
    arr = np.atleast_1d(np.asarray(values, dtype=np.float64))
    if arr.size == 1:
        arr = np.repeat(arr, len(names))
    if arr.size != len(names):
        raise ValueError(f"{what} has {arr.size} values for {len(names)} modalities")
    return arr.tolist()


def _as_source(value: Any, where: str) -> TransferSource:
    if isinstance(value, TransferSource):
        return value
    if isinstance(value, tuple) and len(value) == 2 and np.ndim(value[1]) == 0:
        return TransferSource(value[0], transfer_lambda=value[1])
    raise TypeError(
        f"{where} must be a TransferSource, an (X, transfer_lambda) tuple or a list of those, "
        f"got {type(value).__name__}"
    )


def _normalise_sources(
    sources: Mapping[Any, Any] | None, classes: np.ndarray, n_features: int, lambda_free: bool
) -> dict[Any, list[TransferSource]]:
    """Class label -> list of checked sources with names (``source<k>`` by default)."""
    used: dict[Any, list[TransferSource]] = {}
    for label, value in (sources or {}).items():
        where = f"sources[{label!r}]"
        if np.flatnonzero(classes == label).size != 1:
            raise ValueError(
                f"sources: class {label!r} does not occur in y (classes: {classes.tolist()})"
            )
        items = value if isinstance(value, list) else [value]
        if not items:
            continue
        out = []
        for k, item in enumerate(items):
            src = _as_source(item, where)
            if src.X.shape[1] != n_features:
                raise ValueError(f"{where}.X has {src.X.shape[1]} features, expected {n_features}")
            if src.transfer_lambda is None and not lambda_free:
                raise ValueError(
                    f"{where}: transfer_lambda is required while λ is fixed "
                    "(fixed includes 'transfer_lambda')"
                )
            name = src.name if src.name is not None else f"source{k}"
            out.append(TransferSource(src.X, src.y, src.transfer_lambda, name=name))
        names = [s.name for s in out]
        if len(set(names)) != len(names):
            raise ValueError(f"{where}: source names must differ, got {names}")
        used[label] = out
    return used


def _start_lambda(source: TransferSource) -> float:
    """λ's initial value: the source's, or the middle of [0, 1] when it is to be learned."""
    return 0.5 if source.transfer_lambda is None else float(source.transfer_lambda)


class _NotFitted(NotFittedError, _SklearnNotFitted):
    """Both the project's and scikit-learn's "not fitted" error, so either can be caught."""


def _check_classification_targets(y: np.ndarray) -> None:
    """scikit-learn's ``check_classification_targets`` without its cost in the common case: a
    1-D array of integers, booleans or strings is always "binary" or "multiclass", which it
    accepts. (It costs ~0.8 ms, a fifth of a small fit in the learning loop, which refits
    after every observation.) Anything else (floats, objects, 2-D) goes through it."""
    if y.ndim == 1 and y.dtype.kind in "biuU":
        return
    check_classification_targets(y)


#: ``_validate``'s "no target given" (``y=None`` is a user's mistake that scikit-learn reports).
_NO_TARGET: Any = object()


def _validate(estimator: BaseEstimator, X: Any, y: Any = _NO_TARGET, *, reset: bool) -> Any:
    """scikit-learn's ``validate_data`` (float64, non-finite values allowed), without its cost
    in the common case: a non-empty 2-D float64 ndarray, and for ``fit`` a 1-D array of
    integers, booleans or strings of the same length. For those its checks reduce to the
    number of features, and there are no feature names to record or compare; it costs
    ~0.3 ms a call (dataframe detection), a sixth of a small run of the learning loop, which
    validates at every refit and prediction. Anything else, and any estimator fitted with
    feature names, goes through it."""
    plain = (
        type(X) is np.ndarray
        and X.dtype == np.float64
        and X.ndim == 2
        and X.shape[0] > 0
        and X.shape[1] > 0
        and not hasattr(estimator, "feature_names_in_")
    )
    if y is not _NO_TARGET:
        plain = plain and (
            type(y) is np.ndarray
            and y.ndim == 1
            and y.dtype.kind in "biuU"
            and y.shape[0] == X.shape[0]
        )
    if not plain:
        if y is _NO_TARGET:
            return validate_data(
                estimator, X, reset=reset, dtype=np.float64, ensure_all_finite=False
            )
        return validate_data(estimator, X, y, dtype=np.float64, ensure_all_finite=False)
    if reset:
        estimator.n_features_in_ = X.shape[1]
    elif X.shape[1] != estimator.n_features_in_:
        raise ValueError(
            f"X has {X.shape[1]} features, but {type(estimator).__name__} is expecting "
            f"{estimator.n_features_in_} features as input."
        )
    return X if y is _NO_TARGET else (X, y)


def _threads(n_jobs: Any) -> int:
    """Threads for ``n_jobs`` by joblib's convention: None -> 1, -1 -> every core, -2 -> all
    but one, and so on; never more than the machine's cores (more threads only share them, and
    each one costs memory: a huge ``n_jobs`` once started threads without end)."""
    if n_jobs is None:
        return 1
    if isinstance(n_jobs, bool) or not isinstance(n_jobs, (int, np.integer)) or n_jobs == 0:
        raise ValueError(f"n_jobs must be None or a non-zero integer, got {n_jobs!r}")
    cores = os.cpu_count() or 1
    if n_jobs > 0:
        return min(int(n_jobs), cores)
    return max(1, cores + 1 + int(n_jobs))


def _real(value: Any, name: str, *, positive: bool = False) -> float:
    """A setting that must be a finite real number (not a bool), > 0 or >= 0."""
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, float, np.integer, np.floating))
        or not np.isfinite(value)
        or not (value > 0 if positive else value >= 0)
    ):
        raise ValueError(
            f"{name} must be a finite number {'>' if positive else '>='} 0, got {value!r}"
        )
    return float(value)


def _count(value: Any, name: str, maximum: int) -> int:
    """A setting that must be an integer (not a bool) in ``0..maximum``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
        raise ValueError(f"{name} must be a non-negative integer, got {value!r}")
    if value > maximum:
        raise ValueError(f"{name} must be at most {maximum}, got {value}")
    return int(value)


def check_optimizer_tol(value: Any) -> None:
    """The optimiser's relative tolerance must be a finite real number >= 0 (not a bool)."""
    _real(value, "optimizer_tol")


def _seed(random_state: Any) -> int:
    if random_state is None:
        return int(np.random.SeedSequence().generate_state(1, np.uint64)[0])
    if isinstance(random_state, (int, np.integer)):
        if random_state < 0:
            raise ValueError(f"random_state must be >= 0, got {random_state}")
        return int(random_state) & 0xFFFF_FFFF_FFFF_FFFF
    if isinstance(random_state, np.random.Generator):
        return int(random_state.integers(0, 2**63))
    if isinstance(random_state, np.random.RandomState):
        return int(random_state.randint(0, 2**31 - 1))
    raise TypeError(
        f"random_state must be None, an int or a numpy Generator, got {type(random_state).__name__}"
    )


class LaplaceGPC(ClassifierMixin, BaseEstimator):
    """One-vs-all Gaussian-process classifier with the Laplace approximation.

    A scikit-learn classifier: ``get_params``/``set_params``, ``clone``, ``score``,
    pipelines, grid search and cross-validation work as for any other.

    Parameters
    ----------
    length_scale : float, "auto" or sequence of float
        Initial RBF length-scale (one per modality, or one for all). ``"auto"`` (default) starts
        at the median pairwise distance of each modality.
    signal_variance : float
        Initial signal variance σ² (the kernel's amplitude).
    modalities : None, mapping name -> columns, or sequence of column lists
        Groups of feature columns with their own RBF kernel. ``None``: one group of all columns.
    modality_weights : sequence of float, optional
        Initial weights γ (normalised to sum to 1); uniform by default.
    optimize : bool
        Maximise the log marginal likelihood over the free hyper-parameters.
    n_restarts : int
        Starts besides the initial hyper-parameters (default 1): the first is scaled to the
        data (median pairwise distance per modality; random around it when the initial
        length-scale is already "auto"), the others are random around that scale. At most
        :data:`MAX_RESTARTS`.
    fixed : iterable of str
        Hyper-parameters held at their initial values, among ``"signal_variance"``,
        ``"length_scale"``, ``"modality_weights"``, ``"transfer_lambda"``. By default λ is fixed
        (the APTKT method sets it from the prior models' predictions).
    random_state : None, int or numpy Generator
        Seeds the random starts; the fit is deterministic for a given value.
    max_iter : int
        Iterations of the quasi-Newton optimiser per start (default 100; at most
        :data:`MAX_ITERATIONS`).
    optimizer_tol : float
        The optimiser stops when an iteration lowers the negative log marginal likelihood (or
        posterior) by less than this fraction of its value; default 1e7·eps ≈ 2.2e-9, the
        stopping rule of scipy's L-BFGS-B as scikit-learn calls it. (It also stops when the
        projected gradient's largest component is below 1e-5.)
    length_scale_bounds, signal_variance_bounds : (float, float)
        Box constraints of the optimiser.
    newton_max_iter, newton_tol : int, float
        Newton mode-finding limits (Algorithm 3.1): at most :data:`MAX_ITERATIONS`, and a
        finite tolerance >= 0. Every numeric setting is checked when ``fit`` starts: NaN,
        infinity, a bool or a value out of range is a :class:`ValueError` naming it.
    max_jitter : float
        If a kernel cannot be factorised, jitter of 1e-10, 1e-8, ... times the signal variance
        is added to its diagonal up to this bound, then
        :class:`~aptkt.gp.KernelNotPositiveDefiniteError` is raised.
    approximation : {"erf", "quadrature"}
        Predictive integral ``∫σ(f)N(f|μ,s²)df``: the five-erf mixture (as scikit-learn; error
        ~1e-5) or Gauss-Legendre quadrature of the exact integrand (error < 1e-9).
    n_jobs : int, optional
        Threads for the per-class fits, by joblib's convention: None (default) one, -1 every
        core, -2 all but one, ...; never more than the machine's cores.

    A fit whose n x n matrices would not fit in the memory available raises
    :class:`~aptkt.errors.ProblemTooLargeError` naming the rows and the bytes needed, before
    allocating them.
    hyper_prior : None, "weak" or HyperPrior
        None: plain ML-II (maximise the log marginal likelihood). Otherwise MAP-II with the
        given weak log-normal hyper-priors (see :class:`HyperPrior`).
    class_prior : {"training", "uniform"}
        How often each class is taken to occur when the one-vs-all probabilities are combined
        into ``predict_proba``. "training" (default, as scikit-learn): as the classifiers
        learnt it, i.e. as often as among the training labels. "uniform": each binary
        classifier's odds are moved from its training labels' base rate to 1 / K before
        normalising (the prior-shift adjustment of Saerens, Latinne & Decaestecker, 2002) — for
        training sets whose class counts were chosen by whoever collected them (an active
        learner), not drawn from the classes' frequencies. A classifier's base rate is the
        share of positives among *all* the labels it was fitted on, its source tasks' rows
        included (``base_rates_``). With equal class counts and no sources both settings agree.
        ``predict_proba_binary`` is not adjusted, and ``predict_proba(X,
        class_prior="training")`` gives the unadjusted posterior whatever the setting.
    latent_mean : {"zero", "base-rate"}
        The constant prior mean m of each binary classifier's latent function, f ~ GP(m, K).
        "zero" (default, as scikit-learn): far from its training rows every classifier returns
        ½, whatever its labels. "base-rate": m = logit ρ̃, the log-odds of the classifier's
        share of positive labels (source rows included) under the Jeffreys prior, ρ̃ = (n₊ +
        ½) / (n + 1): far from its data a classifier returns to the rate it was trained at
        (widened by the latent variance σ²), so its probability carries its base rate
        everywhere — what the "uniform" class prior's adjustment assumes, and what a binary
        relatedness p(y = +1 | x) needs to stay low for observations unlike any of the class's.
        m is a plug-in estimate, not optimised: the marginal likelihood and its gradient are
        those of the GP with this fixed mean (``latent_offset_``).

    Attributes
    ----------
    classes_ : ndarray
        Class labels in sorted order.
    class_counts_ : ndarray of shape (n_classes,)
        Training labels per class (the rows of ``X``; source rows not counted).
    base_rates_ : ndarray of shape (n_classes,)
        Each one-vs-all classifier's share of positive labels among all the rows it was fitted
        on: its class's rows of ``X`` plus its source tasks' positives, over the rows of ``X``
        plus its source tasks' rows. What ``class_prior="uniform"`` moves to 1 / K.
    latent_offset_ : ndarray of shape (n_classifiers,)
        Each classifier's latent prior mean m (zeros with ``latent_mean="zero"``).
    theta_ : ndarray of shape (n_classifiers, n_hyperparameters)
        Fitted hyper-parameters in log space (see ``hyperparameter_names_``); one row per
        one-vs-all classifier (a single classifier when there are two classes and no transfer).
    log_marginal_likelihood_ : ndarray of shape (n_classifiers,)
        Laplace log marginal likelihood of each classifier at ``theta_``, in ``classes_`` order.
    hyperparameter_names_ : list of str
    modality_names_ : list of str
    sources_ : dict
        Transfer sources used, by class label: a list of :class:`TransferSource` each.
    hyperparameters_ : dict
        Fitted hyper-parameters by class label, as named values (see the property).
    n_iter_ : ndarray of shape (n_classifiers,)
        Quasi-Newton iterations of the start that gave each classifier's hyper-parameters.
    log_hyper_prior_ : ndarray of shape (n_classifiers,)
        Log hyper-prior density at ``theta_`` (0 for ML-II).
    """

    def __init__(
        self,
        length_scale: float | str | Sequence[float] = DEFAULTS.length_scale,
        signal_variance: float = DEFAULTS.signal_variance,
        *,
        modalities: Mapping[str, Sequence[int]] | Sequence[Sequence[int]] | None = None,
        modality_weights: Sequence[float] | None = None,
        optimize: bool = True,
        n_restarts: int = DEFAULTS.n_restarts,
        fixed: Iterable[str] = ("transfer_lambda",),
        random_state: Any = None,
        max_iter: int = DEFAULTS.max_iter,
        optimizer_tol: float = DEFAULTS.optimizer_tol,
        length_scale_bounds: tuple[float, float] = (1e-5, 1e5),
        signal_variance_bounds: tuple[float, float] = (1e-5, 1e5),
        newton_max_iter: int = 100,
        newton_tol: float = 1e-10,
        max_jitter: float = 1e-6,
        approximation: str = DEFAULTS.approximation,
        n_jobs: int | None = DEFAULTS.n_jobs,
        hyper_prior: HyperPrior | str | None = DEFAULTS.hyper_prior,
        class_prior: str = DEFAULTS.class_prior,
        latent_mean: str = DEFAULTS.latent_mean,
    ) -> None:
        self.length_scale = length_scale
        self.signal_variance = signal_variance
        self.modalities = modalities
        self.modality_weights = modality_weights
        self.optimize = optimize
        self.n_restarts = n_restarts
        self.fixed = fixed
        self.random_state = random_state
        self.max_iter = max_iter
        self.optimizer_tol = optimizer_tol
        self.length_scale_bounds = length_scale_bounds
        self.signal_variance_bounds = signal_variance_bounds
        self.newton_max_iter = newton_max_iter
        self.newton_tol = newton_tol
        self.max_jitter = max_jitter
        self.approximation = approximation
        self.n_jobs = n_jobs
        self.hyper_prior = hyper_prior
        self.class_prior = class_prior
        self.latent_mean = latent_mean

    # -- scikit-learn conventions -------------------------------------------------------------
    # get_params / set_params / repr / score come from BaseEstimator and ClassifierMixin.
    def __sklearn_is_fitted__(self) -> bool:
        return hasattr(self, "_model")

    #: The fitted core model (``aptkt._core.GpcModel``), set by ``fit`` and ``from_state``.
    _model: Any

    def __getstate__(self) -> dict[str, Any]:
        # The compiled model is rebuilt from plain arrays (what ``save`` writes) on unpickling:
        # joblib and scikit-learn's tools copy estimators between processes this way.
        state = super().__getstate__()
        if "_model" in state:
            state = dict(state)
            del state["_model"]
            state["_fitted_state"] = self.state()
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        state = dict(state)
        arrays = state.pop("_fitted_state", None)
        super().__setstate__(state)
        if arrays is not None:
            self._model = type(self).from_state(arrays)._model

    # -- fitting ------------------------------------------------------------------------------
    def _spec(self, n_features: int) -> dict[str, Any]:
        names, groups = _normalise_modalities(self.modalities, n_features)
        m = len(groups)
        if isinstance(self.length_scale, str):
            if self.length_scale != "auto":
                raise ValueError(
                    f"length_scale must be a number, a sequence or 'auto', got {self.length_scale!r}"
                )
            length_scales = [float("nan")] * m
        else:
            ls = np.atleast_1d(np.asarray(self.length_scale, dtype=np.float64))
            if ls.size == 1:
                ls = np.repeat(ls, m)
            if ls.size != m:
                raise ValueError(f"length_scale has {ls.size} values for {m} modalities")
            if not np.all(np.isfinite(ls) & (ls > 0)):
                raise ValueError(
                    f"length_scale must be 'auto' or finite numbers > 0, got {self.length_scale!r}"
                )
            length_scales = [float(v) for v in ls]
        if self.modality_weights is None:
            weights = [1.0 / m] * m
        else:
            weights = [_real(w, "modality_weights") for w in self.modality_weights]
            if len(weights) != m:
                raise ValueError(f"modality_weights has {len(weights)} values for {m} modalities")
            if sum(weights) <= 0:
                raise ValueError(f"modality_weights must have a positive sum, got {weights}")
        fixed = set(self.fixed)
        unknown = fixed - set(_FIXABLE)
        if unknown:
            raise ValueError(
                f"fixed: unknown hyper-parameter(s) {sorted(unknown)}; choose from {list(_FIXABLE)}"
            )
        self._check_class_prior()
        if self.latent_mean not in LATENT_MEANS:
            raise ValueError(f"latent_mean must be one of {LATENT_MEANS}, got {self.latent_mean!r}")
        if self.approximation not in _APPROXIMATIONS:
            raise ValueError(
                f"approximation must be one of {_APPROXIMATIONS}, got {self.approximation!r}"
            )
        # Every number is checked here, before the core sees it: NaN, infinity or a bool
        # would otherwise pass as a tolerance or a count and surface as a fit that never ends.
        check_optimizer_tol(self.optimizer_tol)
        _real(self.newton_tol, "newton_tol")
        _real(self.max_jitter, "max_jitter")
        _count(self.n_restarts, "n_restarts", MAX_RESTARTS)
        _count(self.max_iter, "max_iter", MAX_ITERATIONS)
        _count(self.newton_max_iter, "newton_max_iter", MAX_ITERATIONS)
        _threads(self.n_jobs)  # checks the value
        bounds = {}
        for name in ("signal_variance_bounds", "length_scale_bounds"):
            value = getattr(self, name)
            if isinstance(value, (str, bytes)) or np.ndim(value) != 1 or len(value) != 2:
                raise ValueError(f"{name} must be a pair (low, high), got {value!r}")
            lo, hi = (_real(v, name, positive=True) for v in value)
            if not lo < hi:
                raise ValueError(f"{name} must satisfy low < high, got {value!r}")
            bounds[name] = (lo, hi)
        return {
            "modality_names": names,
            "modalities": groups,
            "signal_variance": _real(self.signal_variance, "signal_variance", positive=True),
            "length_scales": length_scales,
            "weights": weights,
            "free": {k: k not in fixed for k in _FIXABLE},
            "signal_variance_bounds": bounds["signal_variance_bounds"],
            "length_scale_bounds": bounds["length_scale_bounds"],
            "hyper_prior": HyperPrior.resolve(self.hyper_prior),
        }

    def _settings(self, spec: dict[str, Any]) -> _core.FitSettings:
        """The binding's named settings object for this estimator's parameters."""
        free = spec["free"]
        return _core.FitSettings(
            modalities=spec["modalities"],
            signal_variance=spec["signal_variance"],
            length_scales=spec["length_scales"],
            weights=spec["weights"],
            free_signal_variance=free["signal_variance"],
            free_length_scales=free["length_scale"],
            free_weights=free["modality_weights"],
            free_lambda=free["transfer_lambda"],
            signal_variance_bounds=spec["signal_variance_bounds"],
            length_scale_bounds=spec["length_scale_bounds"],
            optimize=bool(self.optimize),
            n_restarts=int(self.n_restarts),
            seed=_seed(self.random_state),
            max_iter=int(self.max_iter),
            optimizer_tol=float(self.optimizer_tol),
            newton_max_iter=int(self.newton_max_iter),
            newton_tol=float(self.newton_tol),
            max_jitter=float(self.max_jitter),
            approximation=self.approximation,
            n_threads=_threads(self.n_jobs),
            latent_mean=self.latent_mean,
            **(spec["hyper_prior"].settings() if spec["hyper_prior"] is not None else {}),
        )

    def fit(
        self,
        X: Any,
        y: Any,
        sources: Mapping[Any, Any] | None = None,
        *,
        hyperparameters: Mapping[Any, Mapping[str, Any]] | None = None,
    ) -> LaplaceGPC:
        """Fit one binary classifier per class (one in total for two classes without sources).

        ``sources`` maps a class label to a :class:`TransferSource`, to ``(X_source, λ)``
        (positives only), or to a list of those (several sources at once, each with its own
        λ): that class's classifier then also learns from the source tasks through the
        dependent kernel.

        ``hyperparameters`` maps class labels to starting values for their classifier, in the
        form of ``hyperparameters_`` (keys ``signal_variance``, ``length_scales``,
        ``modality_weights``, ``transfer_lambda``; any may be left out, and ``length_scales``
        by name may leave modalities out). Hyper-parameters that
        are fixed stay at these values; the fixed λ always comes from the sources.
        """
        return self._fit(X, y, sources, thetas=None, starts=hyperparameters)

    def _fit(
        self,
        X: Any,
        y: Any,
        sources: Any,
        thetas: np.ndarray | None,
        starts: Mapping[Any, Mapping[str, Any]] | None = None,
    ) -> LaplaceGPC:
        # Non-finite values are left to the core, whose message names the row and column.
        X, y = _validate(self, X, y, reset=True)
        X = np.ascontiguousarray(X)
        _check_classification_targets(y)
        classes, labels, counts = np.unique(y, return_inverse=True, return_counts=True)
        if classes.size < 2:
            raise ValueError(
                f"LaplaceGPC needs at least two classes in y, got only one class: "
                f"{classes.tolist()!r}"
            )
        spec = self._spec(X.shape[1])
        used = _normalise_sources(sources, classes, X.shape[1], spec["free"]["transfer_lambda"])
        source_lists: list[list[tuple[np.ndarray, np.ndarray, float]]] = [
            [] for _ in range(classes.size)
        ]
        for label, lst in used.items():
            k = int(np.flatnonzero(classes == label)[0])
            source_lists[k] = [(s.X, s.labels, _start_lambda(s)) for s in lst]
        transfer = bool(used)
        n_lambdas = max((len(v) for v in used.values()), default=0)
        start_rows = None
        if starts is not None:
            start_rows = self._start_rows(
                starts, classes, spec, transfer, n_lambdas, spec["free"]["transfer_lambda"]
            )
        model = _core.fit_gpc(
            X,
            labels.astype(np.int64),
            int(classes.size),
            source_lists,
            self._settings(spec),
            None if thetas is None else np.ascontiguousarray(thetas, dtype=np.float64),
            start_rows,
        )
        self._model = model
        self.classes_ = classes
        self.class_counts_ = counts
        positives = counts.astype(np.float64)
        totals = np.full(classes.size, float(counts.sum()))
        for label, lst in used.items():
            k = int(np.flatnonzero(classes == label)[0])
            positives[k] += sum(float((s.labels > 0).sum()) for s in lst)
            totals[k] += sum(s.labels.size for s in lst)
        # The training frequencies themselves, whatever the latent mean: with equal counts the
        # "uniform" adjustment must stay the identity (the Jeffreys-smoothed rate of the latent
        # mean is a common shift that normalising would not undo).
        self.base_rates_ = positives / totals
        self.latent_offset_ = np.asarray(model.latent_offset)
        self.n_features_in_ = X.shape[1]
        self.X_train_ = X
        self.y_train_ = y
        self.sources_ = used
        self.modality_names_ = spec["modality_names"]
        self.modalities_ = spec["modalities"]
        self.theta_ = np.asarray(model.theta)
        self.log_marginal_likelihood_ = np.asarray(model.log_marginal_likelihood_value)
        self.log_hyper_prior_ = np.asarray(model.log_hyper_prior)
        self.jitter_ = np.asarray(model.jitter)
        self.converged_ = np.asarray(model.optimizer_converged)
        self.n_evaluations_ = np.asarray(model.evaluations)
        self.n_iter_ = np.asarray(model.iterations)
        self.hyperparameter_names_ = self._names(model.n_lambdas)
        return self

    def _start_rows(
        self,
        starts: Mapping[Any, Mapping[str, Any]],
        classes: np.ndarray,
        spec: dict[str, Any],
        transfer: bool,
        n_lambdas: int,
        lambda_free: bool,
    ) -> list[list[float] | None]:
        """Per-classifier starting theta rows (NaN: the constructor's value) from named values."""
        names = spec["modality_names"]
        m = len(names)
        unknown = [label for label in starts if not np.any(classes == label)]
        if unknown:
            raise ValueError(
                f"hyperparameters: class(es) {unknown!r} do not occur in y "
                f"(classes: {classes.tolist()})"
            )
        positives = [1] if classes.size == 2 and not transfer else range(classes.size)
        rows: list[list[float] | None] = []
        for k in positives:
            given = starts.get(classes[k])
            if given is None and classes.size == 2 and not transfer:
                given = starts.get(classes[0])  # the single classifier serves both classes
            if given is None:
                rows.append(None)
                continue
            bad = set(given) - set(_HYPER_KEYS)
            if bad:
                raise ValueError(
                    f"hyperparameters[{classes[k]!r}]: unknown key(s) {sorted(bad)}; "
                    f"choose from {list(_HYPER_KEYS)}"
                )
            row = [np.nan] * (1 + m + (m if m > 1 else 0) + n_lambdas)
            what = f"hyperparameters[{classes[k]!r}]"
            if "signal_variance" in given:
                row[0] = float(
                    np.log(_positive(given["signal_variance"], f"{what}.signal_variance"))
                )
            if "length_scales" in given:
                ls = _per_modality(
                    given["length_scales"], names, f"{what}.length_scales", partial=True
                )
                row[1 : 1 + m] = [
                    float("nan")
                    if np.isnan(v)
                    else float(np.log(_positive(v, f"{what}.length_scales")))
                    for v in ls
                ]
            if "modality_weights" in given and m > 1:
                w = np.asarray(
                    _per_modality(given["modality_weights"], names, f"{what}.modality_weights"),
                    dtype=np.float64,
                )
                if not (np.all(np.isfinite(w)) and np.all(w >= 0) and w.sum() > 0):
                    raise ValueError(f"{what}.modality_weights must be >= 0 with a positive sum")
                with np.errstate(divide="ignore"):
                    row[1 + m : 1 + 2 * m] = np.maximum(np.log(w / w.sum()), -50.0).tolist()
            if "transfer_lambda" in given and lambda_free and n_lambdas:
                lam = given["transfer_lambda"]
                values = list(lam.values()) if isinstance(lam, Mapping) else np.ravel(lam).tolist()
                for i, v in enumerate(values[:n_lambdas]):
                    row[len(row) - n_lambdas + i] = float(v)
            rows.append(row)
        return rows

    def _names(self, n_lambdas: int) -> list[str]:
        names = ["log_signal_variance"] + [f"log_length_scale[{m}]" for m in self.modality_names_]
        if len(self.modality_names_) > 1:
            names += [f"weight_logit[{m}]" for m in self.modality_names_]
        if n_lambdas == 1:
            names.append("transfer_lambda")
        else:
            names += [f"transfer_lambda[{s}]" for s in range(n_lambdas)]
        return names

    def _check_class_prior(self, override: str | None = None) -> None:
        for value in (self.class_prior,) if override is None else (self.class_prior, override):
            if value not in CLASS_PRIORS:
                raise ValueError(f"class_prior must be one of {CLASS_PRIORS}, got {value!r}")

    def _check_fitted(self) -> None:
        if not hasattr(self, "_model"):
            raise _NotFitted("this LaplaceGPC is not fitted yet; call fit(X, y) first")

    def _test_matrix(self, X: Any) -> np.ndarray:
        self._check_fitted()
        X = _validate(self, X, reset=False)
        return np.ascontiguousarray(X)

    # -- fitted views -------------------------------------------------------------------------
    @property
    def signal_variance_(self) -> np.ndarray:
        """Fitted σ² per classifier."""
        self._check_fitted()
        return np.exp(self.theta_[:, 0])

    @property
    def length_scales_(self) -> np.ndarray:
        """Fitted length-scales, shape (n_classifiers, n_modalities)."""
        self._check_fitted()
        m = len(self.modality_names_)
        return np.exp(self.theta_[:, 1 : 1 + m])

    @property
    def modality_weights_(self) -> np.ndarray:
        """Fitted weights γ (rows sum to 1), shape (n_classifiers, n_modalities)."""
        self._check_fitted()
        m = len(self.modality_names_)
        if m == 1:
            return np.ones((self.theta_.shape[0], 1))
        logits = self.theta_[:, 1 + m : 1 + 2 * m]
        e = np.exp(logits - logits.max(axis=1, keepdims=True))
        return e / e.sum(axis=1, keepdims=True)

    @property
    def hyperparameters_(self) -> dict[Any, dict[str, Any]]:
        """Fitted hyper-parameters by class label, as named natural-scale values.

        Each entry: ``signal_variance`` (float), ``length_scales`` and ``modality_weights``
        (dicts by modality name) and ``transfer_lambda`` (dict by source name; empty for a class
        without sources). With two classes and no transfer one classifier serves both classes,
        and both entries hold its values.
        """
        self._check_fitted()
        sv, ls, gw = self.signal_variance_, self.length_scales_, self.modality_weights_
        n_lambdas = self._model.n_lambdas
        single = self.theta_.shape[0] == 1
        out: dict[Any, dict[str, Any]] = {}
        for k, label in enumerate(self.classes_.tolist()):
            r = 0 if single else k
            srcs = self.sources_.get(label, [])
            lambdas: Any = self.theta_[r, self.theta_.shape[1] - n_lambdas :] if n_lambdas else []
            out[label] = {
                "signal_variance": float(sv[r]),
                "length_scales": {m: float(v) for m, v in zip(self.modality_names_, ls[r])},
                "modality_weights": {m: float(v) for m, v in zip(self.modality_names_, gw[r])},
                "transfer_lambda": {s.name: float(v) for s, v in zip(srcs, lambdas)},
            }
        return out

    # -- prediction ---------------------------------------------------------------------------
    def predict_proba_binary(self, X: Any) -> np.ndarray:
        """Each one-vs-all classifier's own ``p(y = +1 | x)``, shape (n_samples, n_classes).

        Not normalised across classes (rows need not sum to one): the probability that a
        binary classifier gives its own class, as relatedness needs it. With two classes and
        a single classifier, the first column is the complement of the second.
        """
        self._check_fitted()
        return np.asarray(self._model.predict_proba_binary(self._test_matrix(X)))

    def predict_proba(self, X: Any, *, class_prior: str | None = None) -> np.ndarray:
        """Class probabilities (n_samples, n_classes): one-vs-all probabilities normalised,
        after the ``class_prior`` adjustment (the estimator's setting unless given here; the
        training observations themselves, drawn with the training frequencies, are scored
        with ``class_prior="training"``)."""
        self._check_fitted()
        self._check_class_prior(class_prior)  # also after fit: set_params may have changed it
        if (self.class_prior if class_prior is None else class_prior) == "uniform":
            return uniform_class_prior(self.predict_proba_binary(X), self.base_rates_)
        return np.asarray(self._model.predict_proba(self._test_matrix(X)))

    def predict(self, X: Any) -> np.ndarray:
        self._check_fitted()
        return self.classes_[np.argmax(self.predict_proba(X), axis=1)]

    def latent(self, X: Any) -> tuple[np.ndarray, np.ndarray]:
        """Latent predictive means and variances per classifier, each (n_samples, n_classifiers)."""
        self._check_fitted()
        mean, var = self._model.latent(self._test_matrix(X))
        return np.asarray(mean), np.asarray(var)

    def log_marginal_likelihood(
        self, theta: Any = None, eval_gradient: bool = False, *, include_prior: bool = False
    ) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """Laplace log marginal likelihood of every classifier, in ``classes_`` order.

        ``theta``: None (the fitted values), one row applied to every classifier, or one row
        per classifier. With ``eval_gradient`` also returns the gradient with respect to every
        entry of theta (fixed ones included), shape (n_classifiers, n_hyperparameters). With
        ``include_prior``, the log hyper-prior is added: the objective MAP-II maximises.
        """
        self._check_fitted()
        if theta is None and not eval_gradient:
            lml = self.log_marginal_likelihood_.copy()
            return lml + self.log_hyper_prior_ if include_prior else lml
        t = self.theta_ if theta is None else np.asarray(theta, dtype=np.float64)
        if t.ndim == 1:
            t = np.tile(t, (self.theta_.shape[0], 1))
        if t.shape != self.theta_.shape:
            raise ValueError(
                f"theta must have shape {self.theta_.shape[1:]} or {self.theta_.shape}, got {t.shape}"
            )
        lml, grad = self._model.log_marginal_likelihood(
            np.ascontiguousarray(t), bool(eval_gradient), bool(include_prior)
        )
        return (np.asarray(lml), np.asarray(grad)) if eval_gradient else np.asarray(lml)

    # -- persistence (no pickle) --------------------------------------------------------------
    def state(self) -> dict[str, np.ndarray]:
        """Arrays and JSON metadata that rebuild this fitted model exactly (see :meth:`from_state`)."""
        self._check_fitted()
        source_meta = []
        arrays = {
            "X": self.X_train_,
            "y": np.searchsorted(self.classes_, self.y_train_).astype(np.int64),
            "theta": self.theta_,
        }
        i = 0
        for label, lst in self.sources_.items():
            for src in lst:
                source_meta.append(
                    {
                        "class": _jsonable(label),
                        "name": src.name,
                        "transfer_lambda": src.transfer_lambda,
                        "labelled": src.y is not None,
                    }
                )
                arrays[f"source_X_{i}"] = src.X
                if src.y is not None:
                    arrays[f"source_y_{i}"] = src.y
                i += 1
        meta = {
            "format": _SAVE_FORMAT,
            "params": {
                k: _jsonable(v)
                for k, v in self.get_params().items()
                # class_prior, latent_mean and optimizer_tol at their defaults are left out:
                # files stay readable by the versions before them, which share this format (and
                # the prior files' keys).
                if k != "random_state"
                and not (k in _OMITTED_AT_DEFAULT and v == getattr(DEFAULTS, k))
            },
            "classes": self.classes_.tolist(),
            "sources": source_meta,
        }
        arrays["meta"] = np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)
        return arrays

    @classmethod
    def from_state(cls, arrays: Mapping[str, np.ndarray]) -> LaplaceGPC:
        """Rebuild a model from :meth:`state`'s arrays (this format or version 1)."""
        meta = json.loads(bytes(np.asarray(arrays["meta"], dtype=np.uint8)).decode())
        fmt = meta.get("format")
        if fmt != _SAVE_FORMAT and fmt not in _OLD_FORMATS:
            raise ValueError(f"not a saved LaplaceGPC (format {fmt!r})")
        params = dict(meta["params"])
        params["fixed"] = tuple(params["fixed"])
        for key in ("length_scale_bounds", "signal_variance_bounds"):
            params[key] = tuple(params[key])
        if isinstance(params.get("hyper_prior"), Mapping):
            # Files written before the modality-weight prior existed had flat weights.
            params["hyper_prior"] = HyperPrior(
                **{"modality_weight_sd": None, **params["hyper_prior"]}
            )
        model = cls(**params)
        classes = np.asarray(meta["classes"])
        y = classes[np.asarray(arrays["y"])]
        sources: dict[Any, list[TransferSource]] = {}
        if fmt == "aptkt.LaplaceGPC/1":  # one positives-only source per class
            for i, label in enumerate(meta["source_classes"]):
                lam = float(arrays[f"source_lambda_{i}"])
                sources[label] = [TransferSource(np.asarray(arrays[f"source_X_{i}"]), None, lam)]
        else:
            for i, entry in enumerate(meta["sources"]):
                src = TransferSource(
                    np.asarray(arrays[f"source_X_{i}"]),
                    np.asarray(arrays[f"source_y_{i}"]) if entry["labelled"] else None,
                    entry["transfer_lambda"],
                    name=entry["name"],
                )
                sources.setdefault(entry["class"], []).append(src)
        return model._fit(np.asarray(arrays["X"]), y, sources, thetas=np.asarray(arrays["theta"]))

    def save(self, path: str | Path) -> None:
        """Save to a ``.npz`` file (arrays + JSON; loading executes no code)."""
        arrays: dict[str, Any] = self.state()
        np.savez_compressed(Path(path), **arrays)

    @classmethod
    def load(cls, path: str | Path) -> LaplaceGPC:
        if not zipfile.is_zipfile(path):
            raise ValueError(f"{path}: not a saved LaplaceGPC (not an .npz archive)")
        with np.load(Path(path), allow_pickle=False) as data:
            return cls.from_state({k: data[k] for k in data.files})


def uniform_class_prior(binary: np.ndarray, base_rates: np.ndarray) -> np.ndarray:
    """One-vs-all probabilities (n_samples, K) of classifiers whose training labels were
    positive at the rates ``base_rates`` (K,), each rate replaced by 1 / K (in log-odds), then
    normalised over the classes. A probability of exactly 0 or 1 stays there. (Without source
    tasks the rates are the class counts over their sum.)"""
    rates = np.asarray(base_rates, dtype=np.float64)
    if rates.ndim != 1 or not np.all((rates > 0) & (rates < 1)):
        raise ValueError(f"base_rates must be K rates strictly between 0 and 1, got {rates}")
    k = rates.size
    shift = np.log(1.0 / (k - 1)) - np.log(rates / (1.0 - rates))
    adjusted = expit(logit(np.asarray(binary, dtype=np.float64)) + shift)
    total = adjusted.sum(axis=1, keepdims=True)
    uniform = np.full_like(adjusted, 1.0 / k)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(total > 0, adjusted / total, uniform)


def _jsonable(value: Any) -> Any:
    if isinstance(value, HyperPrior):
        return asdict(value)
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, set, frozenset)):
        return [_jsonable(v) for v in value]
    if isinstance(value, range):
        return list(value)
    return value


def kernel_matrix(
    X: Any,
    theta: Any,
    *,
    modalities: Mapping[str, Sequence[int]] | Sequence[Sequence[int]] | None = None,
    n_source: int | Sequence[int] = 0,
) -> np.ndarray:
    """The kernel matrix of ``X`` at ``theta`` (layout as ``LaplaceGPC.theta_``).

    ``n_source``: the first rows of ``X`` that belong to source tasks, as one count (a single
    source task) or a sequence of counts (several source tasks in order); the remaining rows
    are the target task. Theta then ends with one λ ∈ [-1, 1] per source task.
    """
    X = _as_matrix(X, "X")
    _, groups = _normalise_modalities(modalities, X.shape[1])
    if isinstance(n_source, (int, np.integer)):
        sizes = [int(n_source)] if int(n_source) > 0 else []
    else:
        sizes = [int(v) for v in n_source]
    if any(v < 0 for v in sizes):
        raise ValueError(f"n_source must hold counts >= 0, got {n_source!r}")
    return np.asarray(_core.kernel_matrix(X, [float(v) for v in np.ravel(theta)], groups, sizes))
