"""APTKT as a scikit-learn classifier: learn new objects from your own arrays with a library's
prior knowledge, without the active loop.

:class:`APTKTClassifier` fits what the learner fits for one action after it has observed the
rows given: the new objects' model in the library's feature space, each new object's
classifier with the most related old object transferred where the cut-off lets it through
(Eq. 3), through the dependent kernel (Eq. 2). Without a library it is the paper's baseline,
a Gaussian-process classifier in the new objects' own feature space. Which rows to observe
next is left to the user; :class:`~aptkt.learning.learner.APTKT` chooses them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from sklearn.base import BaseEstimator, ClassifierMixin, clone

from aptkt.errors import InvalidInputError, InvalidTypeError, UnknownNameError
from aptkt.gp.inputs import NotFitted, check_classification_targets, validate
from aptkt.learning.config import GPSettings, LearnerConfig
from aptkt.learning.learner import ActionLearner
from aptkt.learning.observations import Observations
from aptkt.learning.prior import ActionPrior, PriorKnowledge
from aptkt.learning.transfer import TRANSFER_MODES, TransferDecision

__all__ = ["APTKTClassifier"]

#: The name of the one modality of features given without a library or column groups.
FEATURES = "features"


class APTKTClassifier(ClassifierMixin, BaseEstimator):
    """A scikit-learn classifier of new objects that learns with prior tactile knowledge.

    Parameters
    ----------
    prior : PriorKnowledge or None
        The library of old objects. None: the baseline, a Gaussian-process classifier that
        knows nothing beforehand (whatever ``transfer`` says).
    action : str or None
        The library's action whose features ``X`` holds; needed when the library has several.
    modalities : mapping name -> column indices, or None
        Without a library: groups of ``X``'s columns with a kernel each (the multi-modal
        kernel, Eq. 1); None: one group of every column. With a library the columns are the
        library's (its modalities side by side, in its order), and this must be None.
    transfer : {"paper", "control", "none"}
        "paper": transfer from the most related old object (Eq. 2-3); "control": the library's
        feature space and kernel without transfer; "none": the baseline, nothing of the library
        but its columns.
    cutoff : {"same-object", "evidence", "paper"}
        When a related old object is transferred (see :class:`~aptkt.learning.LearnerConfig`).
    eps_neg, evidence_margin : float
        Eq. 3's cut-off and the log odds the second cut-off must exceed
        (:class:`~aptkt.learning.LearnerConfig`).
    auxiliary : bool
        Add the library models' posteriors as an extra modality (Eq. 5); needs a library.
    gp : GPSettings or None
        How the Gaussian processes are fitted; None: the library's own settings (the defaults
        without a library).
    random_state : int, numpy RandomState or None
        Seeds the optimiser's starts; None is 0, so that fits are repeatable.

    Attributes
    ----------
    classes_ : ndarray
        The class labels, sorted.
    n_features_in_ : int
        Columns of ``X``.
    action_ : str or None
        The library's action used (None without a library).
    modalities_ : dict
        Modality name -> the columns of ``X`` it holds.
    transfer_ : dict
        Class label -> :class:`~aptkt.learning.TransferDecision`: the old object transferred
        (``source``, None if none) and its λ (``transfer_lambda``). Empty without transfer.
    feature_space_ : str
        "prior" (the library's feature space) or "new" (fitted on ``X``, the baseline's).
    uses_auxiliary_ : bool
        Whether the model kept the auxiliary features.
    model_ : LaplaceGPC
        The fitted one-vs-all classifier, in the feature space (its classes are the labels as
        text).
    """

    def __init__(
        self,
        prior: PriorKnowledge | None = None,
        action: str | None = None,
        *,
        modalities: Mapping[str, Sequence[int]] | None = None,
        transfer: str = "paper",
        cutoff: str = "same-object",
        eps_neg: float = 0.5,
        evidence_margin: float = 3.0,
        auxiliary: bool = False,
        gp: GPSettings | None = None,
        random_state: Any = None,
    ) -> None:
        self.prior = prior
        self.action = action
        self.modalities = modalities
        self.transfer = transfer
        self.cutoff = cutoff
        self.eps_neg = eps_neg
        self.evidence_margin = evidence_margin
        self.auxiliary = auxiliary
        self.gp = gp
        self.random_state = random_state

    def __sklearn_clone__(self) -> APTKTClassifier:
        # A library is large and only read: clones (one per fold of a cross-validation) share
        # it, with the models and tables it has computed, rather than copy it.
        params = self.get_params(deep=False)
        prior = params.pop("prior")
        return type(self)(prior=prior, **{k: clone(v, safe=False) for k, v in params.items()})

    def __sklearn_is_fitted__(self) -> bool:
        return hasattr(self, "_learner")

    # -- fitting -------------------------------------------------------------------------------
    def fit(self, X: Any, y: Any) -> APTKTClassifier:
        """Fit the new objects' model on features ``X`` (n, d) labelled ``y`` (n,): at least
        two classes, the library's columns with a library."""
        config = self._config()
        X, y = _validated(self, X, y, fitting=True)
        try:
            check_classification_targets(y)
        except ValueError as exc:
            raise InvalidInputError(str(exc)) from None
        classes = np.unique(y)
        if classes.size < 2:
            raise InvalidInputError(
                f"y holds one class ({classes.tolist()!r}); a classifier needs at least two"
            )
        # The learner names objects by text; distinct labels of one valid target type (numbers,
        # text or booleans; scikit-learn refuses a mixture) are distinct as text.
        names = [str(c) for c in classes]
        _check_finite(X)
        action, groups, prior_action = self._columns(X.shape[1])
        extraction = prior_action.observations.extraction if prior_action is not None else None
        learner = ActionLearner(
            action,
            names,
            config,
            prior_action if config.uses_prior else None,
            extraction=extraction,
        )
        learner.observations = self._observations(action, X, y, groups, extraction)
        learner.update(step=0)
        model = learner.model
        assert model is not None  # update fitted it
        where = {str(c): k for k, c in enumerate(model.classes_)}
        self._learner = learner
        self._order = np.array([where[n] for n in names])
        self._extraction = extraction
        self.classes_ = classes
        self.action_ = action if prior_action is not None else None
        self.modalities_ = {m: list(cols) for m, cols in groups.items()}
        self.transfer_: dict[Any, TransferDecision] = {
            c: learner.decisions[n]
            for c, n in zip(classes.tolist(), names)
            if n in learner.decisions
        }
        self.feature_space_ = learner.space
        self.uses_auxiliary_ = learner.uses_auxiliary
        self.model_ = model
        return self

    def _config(self) -> LearnerConfig:
        if self.prior is not None and not isinstance(self.prior, PriorKnowledge):
            raise InvalidTypeError(
                f"prior must be a PriorKnowledge or None, got {type(self.prior).__name__}"
            )
        if self.gp is not None and not isinstance(self.gp, GPSettings):
            raise InvalidTypeError(f"gp must be a GPSettings or None, got {type(self.gp).__name__}")
        if self.transfer not in TRANSFER_MODES:
            # Checked here too: without a library the setting is not passed on.
            raise InvalidInputError(
                f"transfer must be one of {TRANSFER_MODES}, got {self.transfer!r}"
            )
        if not isinstance(self.auxiliary, bool):
            raise InvalidTypeError(f"auxiliary must be True or False, got {self.auxiliary!r}")
        if self.prior is None and self.auxiliary:
            raise InvalidInputError("auxiliary features are the library's posteriors: pass prior=")
        gp = self.gp or (self.prior.gp_settings if self.prior is not None else GPSettings())
        return LearnerConfig(
            transfer=self.transfer if self.prior is not None else "none",
            cutoff=self.cutoff,
            eps_neg=float(self.eps_neg),
            evidence_margin=float(self.evidence_margin),
            auxiliary=self.auxiliary,
            budget=0,
            seed=_seed(self.random_state),
            gp=gp,
        )

    def _columns(self, n_columns: int) -> tuple[str, dict[str, list[int]], ActionPrior | None]:
        """The action, the columns of each modality, and the library's prior of the action."""
        if self.prior is None:
            return self.action or FEATURES, _groups(self.modalities, n_columns), None
        if self.modalities is not None:
            raise InvalidInputError(
                "with a library the columns are its modalities'; leave modalities=None"
            )
        actions = list(self.prior.actions)
        if self.action is None:
            if len(actions) > 1:
                raise InvalidInputError(
                    f"the library has several actions ({', '.join(actions)}): say which one "
                    "the features belong to with action="
                )
            action = actions[0]
        elif self.action not in self.prior:
            raise UnknownNameError(
                f"the library has no action {self.action!r}; it has {', '.join(actions)}"
            )
        else:
            action = self.action
        prior_action = self.prior[action]
        obs = prior_action.observations
        groups, start = {}, 0
        for m in obs.modality_names:
            width = obs.modalities[m].shape[1]
            groups[m] = list(range(start, start + width))
            start += width
        if n_columns != start:
            parts = ", ".join(f"{m} ({len(c)})" for m, c in groups.items())
            raise InvalidInputError(
                f"X has {n_columns} columns, but the library's action {action!r} has {start} "
                f"feature columns: {parts}, side by side in that order"
            )
        return action, groups, prior_action

    @staticmethod
    def _observations(
        action: str,
        X: np.ndarray,
        y: Any,
        groups: Mapping[str, list[int]],
        extraction: str | None,
    ) -> Observations:
        labels = np.asarray([str(v) for v in y]) if y is not None else np.full(len(X), "?")
        return Observations(
            action,
            {m: X[:, cols] for m, cols in groups.items()},
            labels,
            np.arange(len(X)),
            extraction,
        )

    # -- prediction ----------------------------------------------------------------------------
    def predict_proba(self, X: Any) -> np.ndarray:
        """Class posteriors of the rows of ``X``, (n, classes) in ``classes_`` order."""
        if not self.__sklearn_is_fitted__():
            raise NotFitted("this APTKTClassifier is not fitted yet; call fit(X, y) first")
        X = _validated(self, X)
        _check_finite(X)
        learner = self._learner
        obs = self._observations(learner.action, X, None, self.modalities_, self._extraction)
        return learner.predict_proba(obs)[:, self._order]

    def predict(self, X: Any) -> np.ndarray:
        """The most probable class of each row of ``X``."""
        proba = self.predict_proba(X)
        return self.classes_[np.argmax(proba, axis=1)]


def _validated(estimator: APTKTClassifier, X: Any, y: Any = None, *, fitting: bool = False) -> Any:
    """scikit-learn's checks of the data, its mistakes as the package's typed errors."""
    if fitting and y is None:
        raise InvalidInputError(
            "APTKTClassifier requires y to be passed, but the target y is None: fit(X, y) "
            "learns from labelled rows"
        )
    try:
        if fitting:
            return validate(estimator, X, y, reset=True)
        return validate(estimator, X, reset=False)
    except (InvalidInputError, InvalidTypeError):
        raise
    except TypeError as exc:
        raise InvalidTypeError(str(exc)) from None
    except ValueError as exc:
        raise InvalidInputError(str(exc)) from None


def _check_finite(X: np.ndarray) -> None:
    bad = np.argwhere(~np.isfinite(X))
    if bad.size:
        r, c = (int(v) for v in bad[0])
        value = "NaN" if np.isnan(X[r, c]) else ("inf" if X[r, c] > 0 else "-inf")
        raise InvalidInputError(
            f"X holds {value} in row {r}, column {c}: features must be finite numbers"
        )


def _groups(modalities: Mapping[str, Sequence[int]] | None, n_columns: int) -> dict[str, list[int]]:
    """The column groups asked for without a library, checked against ``X``'s columns."""
    if modalities is None:
        return {FEATURES: list(range(n_columns))}
    if not isinstance(modalities, Mapping) or not modalities:
        raise InvalidTypeError(
            "modalities must map a modality's name to its columns, e.g. "
            f"{{'force': [0], 'thermal': [1, 2]}}; got {modalities!r}"
        )
    groups: dict[str, list[int]] = {}
    seen: set[int] = set()
    for name, cols in modalities.items():
        columns = [int(c) for c in np.atleast_1d(np.asarray(cols))]
        if not columns:
            raise InvalidInputError(f"modality {name!r} has no columns")
        outside = [c for c in columns if not 0 <= c < n_columns]
        if outside:
            raise InvalidInputError(
                f"modality {name!r}: column {outside[0]} is not one of X's {n_columns} columns"
            )
        twice = seen.intersection(columns)
        if twice:
            raise InvalidInputError(f"column {min(twice)} is in two modalities")
        seen.update(columns)
        groups[str(name)] = columns
    return groups


def _seed(random_state: Any) -> int:
    """The learner's seed: an int as it is, None as 0 (fits repeat), a RandomState drawn from."""
    if random_state is None:
        return 0
    if isinstance(random_state, np.random.RandomState):
        return int(random_state.randint(2**31 - 1))
    if isinstance(random_state, (bool, np.bool_)) or not isinstance(
        random_state, (int, np.integer)
    ):
        raise InvalidTypeError(
            f"random_state must be an int, a numpy RandomState or None, got {random_state!r}"
        )
    if random_state < 0:
        raise InvalidInputError(f"random_state must be >= 0, got {random_state}")
    return int(random_state)
