"""Gaussian-process classification with the Laplace approximation (Rust core).

:class:`LaplaceGPC` is a one-vs-all multi-class classifier with the logistic likelihood
(Rasmussen & Williams, Algorithms 3.1, 3.2, 5.1) and the kernels of the APTKT method:

* **multi-modal** (paper Eq. 1): the feature columns are grouped into modalities; each gets an
  RBF kernel with its own length-scale and the kernels are combined as ``Σ γ_m K_m`` with the
  weights ``γ`` on the simplex, times a signal variance;
* **transfer** (paper Eq. 2): a class's binary classifier can be given a *source task*, the
  observations of a related prior object, labelled as positives and coupled to the new data by
  the dependent kernel ``[[K_ss, λ K_st], [λ K_ts, K_tt]]`` with relatedness ``λ ∈ [0, 1]``.

Hyper-parameters are found by maximising each classifier's Laplace log marginal likelihood with
analytic gradients from several starts. The classifiers are fitted in parallel in Rust with the
GIL released. Models are saved with :meth:`LaplaceGPC.save` to a NumPy ``.npz`` file (no pickle).
"""

from __future__ import annotations

import inspect
import json
import zipfile
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from aptkt import _core
from aptkt.errors import KernelNotPositiveDefiniteError, NotFittedError

__all__ = ["LaplaceGPC", "TransferSource", "kernel_matrix", "KernelNotPositiveDefiniteError"]

_FIXABLE = ("signal_variance", "length_scale", "modality_weights", "transfer_lambda")
_APPROXIMATIONS = ("erf", "quadrature")
_SAVE_FORMAT = "aptkt.LaplaceGPC/1"


@dataclass(frozen=True)
class TransferSource:
    """Observations of a related source task (a prior object) for one class's classifier.

    The rows of ``X`` enter that class's binary classifier as positives; ``transfer_lambda``
    (λ ∈ [0, 1]) scales the kernel between them and the new observations.
    """

    X: np.ndarray
    transfer_lambda: float


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


class LaplaceGPC:
    """One-vs-all Gaussian-process classifier with the Laplace approximation.

    Parameters
    ----------
    length_scale : float, "auto" or sequence of float
        Initial RBF length-scale (one per modality, or one for all). ``"auto"`` starts at the
        median pairwise distance of each modality.
    signal_variance : float
        Initial signal variance σ² (the kernel's amplitude).
    modalities : None, mapping name -> columns, or sequence of column lists
        Groups of feature columns with their own RBF kernel. ``None``: one group of all columns.
    modality_weights : sequence of float, optional
        Initial weights γ (normalised to sum to 1); uniform by default.
    optimize : bool
        Maximise the log marginal likelihood over the free hyper-parameters.
    n_restarts : int
        Starts besides the initial hyper-parameters: the first is scaled to the data (median
        pairwise distance per modality), the others are random around that scale.
    fixed : iterable of str
        Hyper-parameters held at their initial values, among ``"signal_variance"``,
        ``"length_scale"``, ``"modality_weights"``, ``"transfer_lambda"``. By default λ is fixed
        (the APTKT method sets it from the prior models' predictions).
    random_state : None, int or numpy Generator
        Seeds the random starts; the fit is deterministic for a given value.
    max_iter : int
        Iterations of the quasi-Newton optimiser per start.
    length_scale_bounds, signal_variance_bounds : (float, float)
        Box constraints of the optimiser.
    newton_max_iter, newton_tol : int, float
        Newton mode-finding limits (Algorithm 3.1).
    max_jitter : float
        If a kernel cannot be factorised, jitter of 1e-10, 1e-8, ... times the signal variance
        is added to its diagonal up to this bound, then
        :class:`~aptkt.gp.KernelNotPositiveDefiniteError` is raised.
    approximation : {"erf", "quadrature"}
        Predictive integral ``∫σ(f)N(f|μ,s²)df``: the five-erf mixture (as scikit-learn; error
        ~1e-5) or Gauss-Legendre quadrature of the exact integrand (error < 1e-9).
    n_jobs : int, optional
        Threads for the per-class fits; default: all cores.

    Attributes
    ----------
    classes_ : ndarray
        Class labels in sorted order.
    theta_ : ndarray of shape (n_classifiers, n_hyperparameters)
        Fitted hyper-parameters in log space (see ``hyperparameter_names_``); one row per
        one-vs-all classifier (a single classifier when there are two classes and no transfer).
    log_marginal_likelihood_ : ndarray of shape (n_classifiers,)
        Laplace log marginal likelihood of each classifier at ``theta_``, in ``classes_`` order.
    hyperparameter_names_ : list of str
    modality_names_ : list of str
    sources_ : dict
        Transfer sources used, by class label.
    """

    def __init__(
        self,
        length_scale: float | str | Sequence[float] = 1.0,
        signal_variance: float = 1.0,
        *,
        modalities: Mapping[str, Sequence[int]] | Sequence[Sequence[int]] | None = None,
        modality_weights: Sequence[float] | None = None,
        optimize: bool = True,
        n_restarts: int = 2,
        fixed: Iterable[str] = ("transfer_lambda",),
        random_state: Any = None,
        max_iter: int = 200,
        length_scale_bounds: tuple[float, float] = (1e-5, 1e5),
        signal_variance_bounds: tuple[float, float] = (1e-5, 1e5),
        newton_max_iter: int = 100,
        newton_tol: float = 1e-10,
        max_jitter: float = 1e-6,
        approximation: str = "erf",
        n_jobs: int | None = None,
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
        self.length_scale_bounds = length_scale_bounds
        self.signal_variance_bounds = signal_variance_bounds
        self.newton_max_iter = newton_max_iter
        self.newton_tol = newton_tol
        self.max_jitter = max_jitter
        self.approximation = approximation
        self.n_jobs = n_jobs

    # -- scikit-learn conventions -------------------------------------------------------------
    @classmethod
    def _param_names(cls) -> list[str]:
        sig = inspect.signature(cls.__init__)
        return [p for p in sig.parameters if p != "self"]

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        return {name: getattr(self, name) for name in self._param_names()}

    def set_params(self, **params: Any) -> LaplaceGPC:
        valid = set(self._param_names())
        for key, value in params.items():
            if key not in valid:
                raise ValueError(
                    f"invalid parameter {key!r} for LaplaceGPC; valid: {sorted(valid)}"
                )
            setattr(self, key, value)
        return self

    def __repr__(self) -> str:
        defaults = {
            name: p.default
            for name, p in inspect.signature(type(self).__init__).parameters.items()
            if name != "self"
        }
        changed = [
            f"{k}={v!r}"
            for k, v in self.get_params().items()
            if not _same(defaults.get(k, inspect.Parameter.empty), v)
        ]
        return f"LaplaceGPC({', '.join(changed)})"

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
            length_scales = [float(v) for v in ls]
        if self.modality_weights is None:
            weights = [1.0 / m] * m
        else:
            weights = [float(w) for w in self.modality_weights]
            if len(weights) != m:
                raise ValueError(f"modality_weights has {len(weights)} values for {m} modalities")
        fixed = set(self.fixed)
        unknown = fixed - set(_FIXABLE)
        if unknown:
            raise ValueError(
                f"fixed: unknown hyper-parameter(s) {sorted(unknown)}; choose from {list(_FIXABLE)}"
            )
        if self.approximation not in _APPROXIMATIONS:
            raise ValueError(
                f"approximation must be one of {_APPROXIMATIONS}, got {self.approximation!r}"
            )
        for name in ("n_restarts", "max_iter", "newton_max_iter"):
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or value < 0:
                raise ValueError(f"{name} must be a non-negative integer, got {value!r}")
        if self.n_jobs is not None and (
            not isinstance(self.n_jobs, (int, np.integer)) or self.n_jobs < 1
        ):
            raise ValueError(f"n_jobs must be None or a positive integer, got {self.n_jobs!r}")
        return dict(
            modality_names=names,
            modalities=groups,
            signal_variance=float(self.signal_variance),
            length_scales=length_scales,
            weights=weights,
            free=tuple(k not in fixed for k in _FIXABLE),
            signal_variance_bounds=tuple(float(v) for v in self.signal_variance_bounds),
            length_scale_bounds=tuple(float(v) for v in self.length_scale_bounds),
        )

    def fit(
        self,
        X: Any,
        y: Any,
        sources: Mapping[Any, TransferSource | tuple[Any, float]] | None = None,
    ) -> LaplaceGPC:
        """Fit one binary classifier per class (one in total for two classes without sources).

        ``sources`` maps a class label to a :class:`TransferSource` (or ``(X_source, λ)``):
        that class's classifier then also learns from the source observations as positives,
        through the dependent kernel.
        """
        return self._fit(X, y, sources, thetas=None)

    def _fit(self, X: Any, y: Any, sources: Any, thetas: np.ndarray | None) -> LaplaceGPC:
        X = _as_matrix(X, "X")
        y = np.asarray(y)
        if y.ndim != 1:
            raise ValueError(f"y must be 1-D, got shape {y.shape}")
        if y.shape[0] != X.shape[0]:
            raise ValueError(f"X has {X.shape[0]} rows but y has {y.shape[0]} labels")
        classes, labels = np.unique(y, return_inverse=True)
        if classes.size < 2:
            raise ValueError(
                f"LaplaceGPC needs at least two classes in y, got only {classes.tolist()!r}"
            )
        spec = self._spec(X.shape[1])
        source_list: list[tuple[np.ndarray, float] | None] = [None] * classes.size
        used: dict[Any, TransferSource] = {}
        for label, src in (sources or {}).items():
            if not isinstance(src, TransferSource):
                src = TransferSource(*src)
            where = np.flatnonzero(classes == label)
            if where.size != 1:
                raise ValueError(
                    f"sources: class {label!r} does not occur in y (classes: {classes.tolist()})"
                )
            lam = float(src.transfer_lambda)
            if not 0.0 <= lam <= 1.0:
                raise ValueError(
                    f"sources[{label!r}]: transfer_lambda must lie in [0, 1], got {lam}"
                )
            xs = _as_matrix(src.X, f"sources[{label!r}].X", X.shape[1])
            source_list[int(where[0])] = (xs, lam)
            used[label] = TransferSource(xs, lam)
        model = _core.fit_gpc(
            X,
            labels.astype(np.int64),
            int(classes.size),
            source_list,
            spec["modalities"],
            spec["signal_variance"],
            spec["length_scales"],
            spec["weights"],
            spec["free"],
            spec["signal_variance_bounds"],
            spec["length_scale_bounds"],
            bool(self.optimize),
            int(self.n_restarts),
            _seed(self.random_state),
            int(self.max_iter),
            int(self.newton_max_iter),
            float(self.newton_tol),
            float(self.max_jitter),
            self.approximation,
            int(self.n_jobs or 0),
            None if thetas is None else np.ascontiguousarray(thetas, dtype=np.float64),
        )
        self._model = model
        self.classes_ = classes
        self.n_features_in_ = X.shape[1]
        self.X_train_ = X
        self.y_train_ = y
        self.sources_ = used
        self.modality_names_ = spec["modality_names"]
        self.modalities_ = spec["modalities"]
        self.theta_ = np.asarray(model.theta)
        self.log_marginal_likelihood_ = np.asarray(model.log_marginal_likelihood_value)
        self.jitter_ = np.asarray(model.jitter)
        self.converged_ = np.asarray(model.optimizer_converged)
        self.n_evaluations_ = np.asarray(model.evaluations)
        self.hyperparameter_names_ = self._names(model.transfer)
        return self

    def _names(self, transfer: bool) -> list[str]:
        names = ["log_signal_variance"] + [f"log_length_scale[{m}]" for m in self.modality_names_]
        if len(self.modality_names_) > 1:
            names += [f"weight_logit[{m}]" for m in self.modality_names_]
        if transfer:
            names.append("transfer_lambda")
        return names

    def _check_fitted(self) -> None:
        if not hasattr(self, "_model"):
            raise NotFittedError("this LaplaceGPC is not fitted yet; call fit(X, y) first")

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

    # -- prediction ---------------------------------------------------------------------------
    def predict_proba(self, X: Any) -> np.ndarray:
        """Class probabilities (n_samples, n_classes): one-vs-all probabilities normalised."""
        self._check_fitted()
        return np.asarray(self._model.predict_proba(_as_matrix(X, "X", self.n_features_in_)))

    def predict(self, X: Any) -> np.ndarray:
        self._check_fitted()
        return self.classes_[np.argmax(self.predict_proba(X), axis=1)]

    def latent(self, X: Any) -> tuple[np.ndarray, np.ndarray]:
        """Latent predictive means and variances per classifier, each (n_samples, n_classifiers)."""
        self._check_fitted()
        mean, var = self._model.latent(_as_matrix(X, "X", self.n_features_in_))
        return np.asarray(mean), np.asarray(var)

    def score(self, X: Any, y: Any) -> float:
        """Mean accuracy."""
        return float(np.mean(self.predict(X) == np.asarray(y)))

    def log_marginal_likelihood(
        self, theta: Any = None, eval_gradient: bool = False
    ) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """Laplace log marginal likelihood of every classifier, in ``classes_`` order.

        ``theta``: None (the fitted values), one row applied to every classifier, or one row
        per classifier. With ``eval_gradient`` also returns the gradient with respect to every
        entry of theta (fixed ones included), shape (n_classifiers, n_hyperparameters).
        """
        self._check_fitted()
        if theta is None and not eval_gradient:
            return self.log_marginal_likelihood_.copy()
        t = self.theta_ if theta is None else np.asarray(theta, dtype=np.float64)
        if t.ndim == 1:
            t = np.tile(t, (self.theta_.shape[0], 1))
        if t.shape != self.theta_.shape:
            raise ValueError(
                f"theta must have shape {self.theta_.shape[1:]} or {self.theta_.shape}, got {t.shape}"
            )
        lml, grad = self._model.log_marginal_likelihood(
            np.ascontiguousarray(t), bool(eval_gradient)
        )
        return (np.asarray(lml), np.asarray(grad)) if eval_gradient else np.asarray(lml)

    # -- persistence (no pickle) --------------------------------------------------------------
    def state(self) -> dict[str, np.ndarray]:
        """Arrays and JSON metadata that rebuild this fitted model exactly (see :meth:`from_state`)."""
        self._check_fitted()
        meta = {
            "format": _SAVE_FORMAT,
            "params": {
                k: _jsonable(v) for k, v in self.get_params().items() if k != "random_state"
            },
            "classes": self.classes_.tolist(),
            "source_classes": [_jsonable(k) for k in self.sources_],
        }
        arrays = {
            "meta": np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8),
            "X": self.X_train_,
            "y": np.searchsorted(self.classes_, self.y_train_).astype(np.int64),
            "theta": self.theta_,
        }
        for i, src in enumerate(self.sources_.values()):
            arrays[f"source_X_{i}"] = src.X
            arrays[f"source_lambda_{i}"] = np.asarray(src.transfer_lambda)
        return arrays

    @classmethod
    def from_state(cls, arrays: Mapping[str, np.ndarray]) -> LaplaceGPC:
        meta = json.loads(bytes(np.asarray(arrays["meta"], dtype=np.uint8)).decode())
        if meta.get("format") != _SAVE_FORMAT:
            raise ValueError(f"not a saved LaplaceGPC (format {meta.get('format')!r})")
        params = dict(meta["params"])
        params["fixed"] = tuple(params["fixed"])
        for key in ("length_scale_bounds", "signal_variance_bounds"):
            params[key] = tuple(params[key])
        model = cls(**params)
        classes = np.asarray(meta["classes"])
        y = classes[np.asarray(arrays["y"])]
        sources = {
            label: TransferSource(
                np.asarray(arrays[f"source_X_{i}"]), float(arrays[f"source_lambda_{i}"])
            )
            for i, label in enumerate(meta["source_classes"])
        }
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


def _same(a: Any, b: Any) -> bool:
    try:
        return bool(a == b)
    except Exception:  # arrays and other ambiguous comparisons
        return a is b


def _jsonable(value: Any) -> Any:
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
    n_source: int = 0,
) -> np.ndarray:
    """The kernel matrix of ``X`` at ``theta`` (layout as ``LaplaceGPC.theta_``).

    With ``n_source > 0`` the first ``n_source`` rows form the source block of the dependent
    transfer kernel and theta's last entry is λ ∈ [0, 1].
    """
    X = _as_matrix(X, "X")
    _, groups = _normalise_modalities(modalities, X.shape[1])
    return np.asarray(
        _core.kernel_matrix(X, [float(v) for v in np.ravel(theta)], groups, int(n_source))
    )
