"""The estimator: :class:`LaplaceGPC`, a scikit-learn classifier over the compiled core's
one-vs-all Laplace GPC — fitting, the fitted hyper-parameters by name, prediction and the
class-prior adjustment."""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from scipy.special import expit, logit
from sklearn.base import BaseEstimator, ClassifierMixin

from aptkt import _core
from aptkt.errors import InvalidInputError
from aptkt.gp import persistence
from aptkt.gp.hyperparameters import hyperparameter_names
from aptkt.gp.hyperparameters import start_rows as hyper_start_rows
from aptkt.gp.inputs import NotFitted, check_classification_targets, validate
from aptkt.gp.settings import DEFAULTS, HyperPrior, check_class_prior, core_settings, fit_spec
from aptkt.gp.sources import kernel_task_lists, normalise_sources, start_lambda

__all__ = ["LaplaceGPC", "uniform_class_prior"]


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
        Columns are given by index, or by name when ``X`` is a DataFrame (names fitted in
        ``feature_names_in_``, as scikit-learn records them).
    modality_weights : sequence of float, optional
        Initial weights γ (normalised to sum to 1); uniform by default.
    optimize : bool
        Maximise the log marginal likelihood over the free hyper-parameters.
    n_restarts : int
        Starts besides the initial hyper-parameters (default 1): the first is scaled to the
        data (median pairwise distance per modality; random around it when the initial
        length-scale is already "auto"), the others are random around that scale. At most
        :data:`~aptkt.gp.MAX_RESTARTS`.
    fixed : iterable of str
        Hyper-parameters held at their initial values, among ``"signal_variance"``,
        ``"length_scale"``, ``"modality_weights"``, ``"transfer_lambda"``. By default λ is fixed
        (the APTKT method sets it from the prior models' predictions).
    random_state : None, int or numpy Generator
        Seeds the random starts; the fit is deterministic for a given value.
    max_iter : int
        Iterations of the quasi-Newton optimiser per start (default 100; at most
        :data:`~aptkt.gp.MAX_ITERATIONS`).
    optimizer_tol : float
        The optimiser stops when an iteration lowers the negative log marginal likelihood (or
        posterior) by less than this fraction of its value; default 1e7·eps ≈ 2.2e-9, the
        stopping rule of scipy's L-BFGS-B as scikit-learn calls it. (It also stops when the
        projected gradient's largest component is below 1e-5.)
    length_scale_bounds, signal_variance_bounds : (float, float)
        Box constraints of the optimiser.
    newton_max_iter, newton_tol : int, float
        Newton mode-finding limits (Algorithm 3.1): at most :data:`~aptkt.gp.MAX_ITERATIONS`,
        and a finite tolerance >= 0. Every numeric setting is checked when ``fit`` starts: NaN,
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

    kernel : {"per-classifier", "shared"}
        "per-classifier" (default, as scikit-learn's one-vs-rest GPC): each binary classifier
        chooses its own hyper-parameters on its own labels. "shared": one set of kernel
        hyper-parameters (σ², the length-scales, the modality weights) for every classifier,
        chosen by maximising the sum of their log marginal likelihoods (plus the hyper-prior,
        once) — the class posterior then compares classifiers that measure similarity the same
        way, and every classifier's labels inform the kernel. Each classifier keeps its own
        latent function and its sources' fixed λ (``fixed`` must include "transfer_lambda").
        ``fit(..., kernel_tasks=...)`` adds other labelled data sets whose classifiers share the
        kernel (and implies "shared").
    tie_length_scales : bool
        With the shared kernel: one length-scale for every modality (default False) — for
        features measured in one unit in every modality (e.g. the noise-whitened space of
        :mod:`aptkt.learning`), where how far apart two observations may lie and still be alike
        is one number. Not with the per-classifier kernel.

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

    Notes
    -----
    A fit whose n x n matrices would not fit in the memory available (with
    ``kernel="shared"``: every task's, held at once) raises
    :class:`~aptkt.errors.ProblemTooLargeError` naming the rows and the bytes needed, before
    allocating them.
    """

    def __init__(
        self,
        length_scale: float | str | Sequence[float] = DEFAULTS.length_scale,
        signal_variance: float = DEFAULTS.signal_variance,
        *,
        modalities: Mapping[str, Sequence[int] | Sequence[str]]
        | Sequence[Sequence[int]]
        | None = None,
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
        kernel: str = DEFAULTS.kernel,
        tie_length_scales: bool = DEFAULTS.tie_length_scales,
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
        self.kernel = kernel
        self.tie_length_scales = tie_length_scales

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

    def fit(
        self,
        X: Any,
        y: Any,
        sources: Mapping[Any, Any] | None = None,
        *,
        hyperparameters: Mapping[Any, Mapping[str, Any]] | None = None,
        kernel_tasks: Sequence[Sequence[Any]] | None = None,
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

        ``kernel_tasks`` lists further labelled data sets ``(X_k, y_k)`` or ``(X_k, y_k,
        sources_k)`` with the same columns, whose one-vs-all classifiers share this model's
        kernel (``kernel="shared"``): their labels inform the hyper-parameters, the model
        itself is fitted to ``X`` and ``y`` only. Their classes need not be this model's.
        """
        if kernel_tasks is not None and hyperparameters is not None:
            raise InvalidInputError("hyperparameters (starts) cannot be combined with kernel_tasks")
        return self._fit(
            X, y, sources, thetas=None, starts=hyperparameters, kernel_tasks=kernel_tasks
        )

    def _fit(
        self,
        X: Any,
        y: Any,
        sources: Any,
        thetas: np.ndarray | None,
        starts: Mapping[Any, Mapping[str, Any]] | None = None,
        kernel_tasks: Sequence[Sequence[Any]] | None = None,
    ) -> LaplaceGPC:
        # Non-finite values are left to the core, whose message names the row and column.
        X, y = validate(self, X, y, reset=True)
        X = np.ascontiguousarray(X)
        check_classification_targets(y)
        classes, labels, counts = np.unique(y, return_inverse=True, return_counts=True)
        if classes.size < 2:
            raise InvalidInputError(
                f"LaplaceGPC needs at least two classes in y, got only one class: "
                f"{classes.tolist()!r}"
            )
        spec = fit_spec(self, X.shape[1])
        used = normalise_sources(sources, classes, X.shape[1], spec["free"]["transfer_lambda"])
        source_lists: list[list[tuple[np.ndarray, np.ndarray, float]]] = [
            [] for _ in range(classes.size)
        ]
        for label, lst in used.items():
            k = int(np.flatnonzero(classes == label)[0])
            source_lists[k] = [(s.X, s.labels, start_lambda(s)) for s in lst]
        transfer = bool(used)
        n_lambdas = max((len(v) for v in used.values()), default=0)
        start_rows = None
        if starts is not None:
            start_rows = hyper_start_rows(
                starts, classes, spec, transfer, n_lambdas, spec["free"]["transfer_lambda"]
            )
        shared = thetas is None and (self.kernel == "shared" or kernel_tasks is not None)
        if shared and spec["free"]["transfer_lambda"]:
            raise InvalidInputError(
                'a shared kernel keeps each classifier\'s λ fixed: include "transfer_lambda" '
                "in fixed"
            )
        if shared and starts is not None:
            raise InvalidInputError(
                'hyperparameters (starts) work with kernel="per-classifier" only'
            )
        if self.tie_length_scales and thetas is None and not shared:
            raise InvalidInputError('tie_length_scales needs kernel="shared"')
        if shared:
            tasks = [(X, labels.astype(np.int64), int(classes.size), source_lists)]
            tasks += kernel_task_lists(kernel_tasks or (), X.shape[1])
            model = _core.fit_gpc_shared(tasks, 0, core_settings(self, spec))
        else:
            model = _core.fit_gpc(
                X,
                labels.astype(np.int64),
                int(classes.size),
                source_lists,
                core_settings(self, spec),
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
        self.hyperparameter_names_ = hyperparameter_names(self.modality_names_, model.n_lambdas)
        return self

    def _check_class_prior(self, override: str | None = None) -> None:
        check_class_prior(self.class_prior, override)

    def _check_fitted(self) -> None:
        if not hasattr(self, "_model"):
            raise NotFitted("this LaplaceGPC is not fitted yet; call fit(X, y) first")

    def _test_matrix(self, X: Any) -> np.ndarray:
        self._check_fitted()
        X = validate(self, X, reset=False)
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
            raise InvalidInputError(
                f"theta must have shape {self.theta_.shape[1:]} or {self.theta_.shape}, got {t.shape}"
            )
        lml, grad = self._model.log_marginal_likelihood(
            np.ascontiguousarray(t), bool(eval_gradient), bool(include_prior)
        )
        return (np.asarray(lml), np.asarray(grad)) if eval_gradient else np.asarray(lml)

    # -- persistence (no pickle, :mod:`aptkt.gp.persistence`) ---------------------------------
    def state(self) -> dict[str, np.ndarray]:
        """Arrays and JSON metadata that rebuild this fitted model exactly (see :meth:`from_state`)."""
        self._check_fitted()
        return persistence.state(self)

    @classmethod
    def from_state(cls, arrays: Mapping[str, np.ndarray]) -> LaplaceGPC:
        """Rebuild a model from :meth:`state`'s arrays (this format or version 1)."""
        model: LaplaceGPC = persistence.from_state(cls, arrays)
        return model

    def save(self, path: str | Path) -> None:
        """Save to a ``.npz`` file (arrays + JSON; loading executes no code)."""
        persistence.save(self, path)

    @classmethod
    def load(cls, path: str | Path) -> LaplaceGPC:
        model: LaplaceGPC = persistence.load(cls, path)
        return model


def uniform_class_prior(binary: np.ndarray, base_rates: np.ndarray) -> np.ndarray:
    """One-vs-all probabilities (n_samples, K) of classifiers whose training labels were
    positive at the rates ``base_rates`` (K,), each rate replaced by 1 / K (in log-odds), then
    normalised over the classes. A probability of exactly 0 or 1 stays there. (Without source
    tasks the rates are the class counts over their sum.)"""
    rates = np.asarray(base_rates, dtype=np.float64)
    if rates.ndim != 1 or not np.all((rates > 0) & (rates < 1)):
        raise InvalidInputError(f"base_rates must be K rates strictly between 0 and 1, got {rates}")
    k = rates.size
    shift = np.log(1.0 / (k - 1)) - np.log(rates / (1.0 - rates))
    adjusted = expit(logit(np.asarray(binary, dtype=np.float64)) + shift)
    total = adjusted.sum(axis=1, keepdims=True)
    uniform = np.full_like(adjusted, 1.0 / k)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(total > 0, adjusted / total, uniform)
