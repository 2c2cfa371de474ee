"""From raw feature observations to the model's input: per-modality transforms fitted on
training observations only (docs/design.md §4).

Per modality, in order: optional ``log10`` of some columns (texture activities span orders of
magnitude), z-scoring of every column, optional PCA (the thermal curve ``[T̄, ∇T̄]`` is reduced
to 10 components, paper §3.2.3) whose scores are divided by the first component's standard
deviation so every modality reaches the kernel on a comparable scale. The fitted parameters
are plain arrays and are saved with the prior knowledge (no pickle).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from aptkt.errors import ConfigError, InvalidInputError, InvalidStateError
from aptkt.learning.observations import Observations

__all__ = [
    "FEATURE_SCALES",
    "ModalityTransform",
    "FeaturePipeline",
    "SKIN_TRANSFORMS",
    "GENERIC_TRANSFORMS",
    "SKIN_EXTRACTION",
    "EXTRACTIONS",
    "transforms_of",
    "noise_whitener",
    "joint_noise_whitener",
    "within_object_residuals",
]


#: The metric of a feature space. "spread": each column divided by its standard deviation over
#: all the rows fitted on; "whiten": each column divided by its pooled standard deviation within
#: each object's rows (the sensor's variation between repeated observations of one object),
#: then each modality's output multiplied by the inverse square root of its pooled
#: within-object covariance (shrunk towards its diagonal), so that the sensor's noise is
#: uncorrelated with unit variance in every direction of each modality — the Mahalanobis metric
#: of the noise, one modality at a time; "whiten-joint": then the noise correlations *between*
#: modalities are removed too (:func:`joint_noise_whitener`), so that noise one contact puts
#: into several modalities at once counts once.
FEATURE_SCALES = ("spread", "whiten", "whiten-joint")
#: How far the noise correlations between modalities are shrunk towards none before they are
#: removed (``(1 − s) C + s diag C``): they are estimated from the old objects only and, unlike a
#: transducer's own noise, they come from the contact — how hard and where the finger touched —
#: which depends on the object.
CROSS_MODAL_SHRINKAGE = 0.2


@dataclass
class ModalityTransform:
    """Transform of one modality. Configuration fields, then fitted ones (trailing underscore)."""

    log_columns: tuple[int, ...] = ()
    pca_components: int | None = None
    mean_: np.ndarray | None = field(default=None, repr=False)
    scale_: np.ndarray | None = field(default=None, repr=False)
    components_: np.ndarray | None = field(default=None, repr=False)
    pca_scale_: float = 1.0

    def _prepare(self, X: np.ndarray) -> np.ndarray:
        X = np.array(X, dtype=np.float64)
        if self.log_columns and max(self.log_columns) >= X.shape[1]:
            raise ConfigError(
                f"a transform takes the log of columns {list(self.log_columns)} of a modality "
                f"of {X.shape[1]} column(s): it is another sensor's (see SKIN_TRANSFORMS)"
            )
        if self.log_columns:
            cols = list(self.log_columns)
            # Clamp at a tiny positive value: a perfectly still accelerometer axis has activity
            # 0 after quantisation, and log10(0) would be -inf.
            X[:, cols] = np.log10(np.maximum(X[:, cols], 1e-12))
        return X

    def fit(
        self,
        X: np.ndarray,
        objects: np.ndarray | None = None,
        whiten: bool = False,
    ) -> ModalityTransform:
        """Fit on the rows of ``X``. ``objects`` (optional, one label per row):
        scale each column by its pooled within-object standard deviation — the noise of
        repeated observations of one object — instead of its spread over all rows. The spread
        is kept where the repeats are too few to estimate a noise (fewer degrees of freedom
        than :data:`MIN_NOISE_DOF` or than objects) and for a column without any noise (one
        that differs between objects but never within one). ``whiten`` (with ``objects``):
        then multiply the output by the inverse square root of its pooled within-object
        covariance (:func:`noise_whitener`)."""
        X = self._prepare(X)
        if X.shape[0] < 1:
            raise InvalidInputError("cannot fit a feature transform on zero observations")
        self.mean_ = X.mean(axis=0)
        scale = X.std(axis=0)
        if objects is not None:
            # Constancy is judged on the spread (below): a column that differs between
            # objects but never within one has no noise, and keeps its spread.
            noise = _noise_scale(X, objects)
            scale = np.where(noise > _rounding_level(self.mean_), noise, scale)
        # A column whose spread is at the level of its values' rounding is constant: scaling
        # by that spread would turn a change in the last digits into a huge z-score.
        self.scale_ = np.where(scale > _rounding_level(self.mean_), scale, 1.0)
        Z = (X - self.mean_) / self.scale_
        self.components_ = None
        self.pca_scale_ = 1.0
        if self.pca_components is not None:
            # Rank of centred data is at most n - 1; keep that many at most.
            k = max(1, min(self.pca_components, X.shape[0] - 1, X.shape[1]))
            _, sv, vt = np.linalg.svd(Z, full_matrices=False)
            first_sd = sv[0] / np.sqrt(max(X.shape[0], 1)) if sv.size else 0.0
            self.components_ = vt[:k]
            self.pca_scale_ = float(first_sd) if first_sd > 1e-12 else 1.0
        if whiten:
            if objects is None:
                raise InvalidInputError(
                    "whitening needs the objects of the rows (the noise's classes)"
                )
            whitener = noise_whitener(self.transform_prepared(X), objects)
            if whitener is not None:
                pca = (
                    self.components_
                    if self.components_ is not None
                    else np.eye(self.mean_.shape[0])
                )
                # One linear map: the whitener after the PCA (and its scale), stored as the
                # components, so that saved transforms keep their format.
                self.components_ = whitener @ pca / self.pca_scale_
                self.pca_scale_ = 1.0
        return self

    def transform_prepared(self, X: np.ndarray) -> np.ndarray:
        """``transform`` of rows that have been through ``_prepare`` already."""
        Z = (X - self.mean_) / self.scale_
        if self.components_ is not None:
            Z = Z @ self.components_.T / self.pca_scale_
        return Z

    @property
    def fitted(self) -> bool:
        return self.mean_ is not None

    @property
    def n_features_out(self) -> int:
        if not self.fitted:
            raise InvalidStateError("transform not fitted")
        if self.components_ is not None:
            return int(self.components_.shape[0])
        assert self.mean_ is not None  # fitted
        return int(self.mean_.shape[0])

    def transform(self, X: np.ndarray) -> np.ndarray:
        if not self.fitted:
            raise InvalidStateError("transform not fitted")
        return self.transform_prepared(self._prepare(X))

    def state(self) -> dict[str, np.ndarray]:
        out: dict[str, Any] = {
            "log_columns": np.asarray(self.log_columns, dtype=np.int64),
            "pca_components": np.asarray(
                -1 if self.pca_components is None else self.pca_components
            ),
        }
        if self.fitted:
            out.update(mean=self.mean_, scale=self.scale_, pca_scale=np.asarray(self.pca_scale_))
            if self.components_ is not None:
                out["components"] = self.components_
        return out

    @classmethod
    def from_state(cls, state: Mapping[str, np.ndarray]) -> ModalityTransform:
        pca = int(state["pca_components"])
        t = cls(tuple(int(c) for c in state["log_columns"]), None if pca < 0 else pca)
        if "mean" in state:
            t.mean_ = np.asarray(state["mean"])
            t.scale_ = np.asarray(state["scale"])
            t.pca_scale_ = float(state["pca_scale"])
            t.components_ = np.asarray(state["components"]) if "components" in state else None
        return t


#: Fewest degrees of freedom (repeated observations beyond each object's first) behind a noise
#: estimate: a standard deviation from d degrees of freedom is uncertain by about 1/√(2d) of
#: itself — ±32 % at 5 — and below that the spread is the safer scale.
MIN_NOISE_DOF = 5


def _rounding_level(mean: np.ndarray) -> np.ndarray:
    """A scale at or below this is the rounding of the column's values, not a spread."""
    return np.maximum(1e-12, 1e-9 * np.abs(mean))


def _noise_scale(X: np.ndarray, objects: np.ndarray) -> np.ndarray:
    """Each column's pooled within-object standard deviation (n − K degrees of freedom for n
    rows of K objects); the plain spread when the repeats give fewer than
    :data:`MIN_NOISE_DOF` degrees of freedom, or fewer than there are objects."""
    labels = np.asarray(objects)
    if labels.shape != (X.shape[0],):
        raise InvalidInputError(
            f"objects must hold one label per row ({X.shape[0]}), got {labels.shape}"
        )
    _, index = np.unique(labels, return_inverse=True)
    n_objects = index.max() + 1
    dof = X.shape[0] - n_objects
    if dof < max(MIN_NOISE_DOF, n_objects):
        return X.std(axis=0)
    means = np.zeros((index.max() + 1, X.shape[1]))
    np.add.at(means, index, X)
    means /= np.bincount(index)[:, None]
    return np.sqrt(((X - means[index]) ** 2).sum(axis=0) / dof)


def within_object_residuals(X: np.ndarray, objects: np.ndarray) -> tuple[np.ndarray, int]:
    """Each row minus its object's mean, and the degrees of freedom (rows − objects)."""
    labels = np.asarray(objects)
    if labels.shape != (X.shape[0],):
        raise InvalidInputError(
            f"objects must hold one label per row ({X.shape[0]}), got {labels.shape}"
        )
    _, index = np.unique(labels, return_inverse=True)
    means = np.zeros((index.max() + 1, X.shape[1]))
    np.add.at(means, index, X)
    means /= np.bincount(index)[:, None]
    return X - means[index], X.shape[0] - (index.max() + 1)


def noise_whitener(Z: np.ndarray, objects: np.ndarray) -> np.ndarray | None:
    """A matrix W with WᵀW the inverse of the pooled within-object covariance of ``Z``'s
    columns (shrunk towards its diagonal), so that ``Z @ W.T`` has uncorrelated unit noise; None where the repeats give too few degrees of freedom
    (:data:`MIN_NOISE_DOF`, and one per object) or no column varies within objects.

    The shrinkage is Ledoit and Wolf's (2004) for the correlation matrix of the residuals,
    towards the identity: the correlations of a few noise columns are estimated from tens of
    repeats, and an unshrunk inverse square root would amplify the noisiest of them. Columns
    without within-object variation pass through unchanged."""
    return _within_object_whitener(Z, objects, shrinkage=None, min_columns=1)


def joint_noise_whitener(
    Z: np.ndarray, objects: np.ndarray, shrinkage: float = CROSS_MODAL_SHRINKAGE
) -> np.ndarray | None:
    """The symmetric inverse square root M of the pooled within-object covariance C of all of
    ``Z``'s columns, its correlations shrunk by ``shrinkage`` towards 0 (``(1 − s) C + s diag
    C``), so that ``Z @ M.T`` has uncorrelated noise of unit variance; None where the repeats give too few degrees of freedom (as
    :func:`noise_whitener`).

    The symmetric root (ZCA whitening) is the whitening whose output columns stay closest to the
    input columns — each output column is the one most correlated with its own input column
    (Kessy, Lewin and Strimmer, *Optimal whitening and decorrelation*, 2018) — so after it the
    columns still belong to their modalities, and a multi-modal kernel (Eq. 1) still weighs the
    modalities. Columns without within-object variation pass through unchanged."""
    if not 0.0 <= shrinkage <= 1.0:
        raise InvalidInputError(f"shrinkage must lie in [0, 1], got {shrinkage}")
    return _within_object_whitener(Z, objects, shrinkage=shrinkage, min_columns=2)


def _within_object_whitener(
    Z: np.ndarray, objects: np.ndarray, *, shrinkage: float | None, min_columns: int
) -> np.ndarray | None:
    """The inverse square root of the pooled within-object covariance of ``Z``'s noisy columns,
    its correlations shrunk by ``shrinkage`` towards none (None: Ledoit and Wolf's intensity),
    embedded in the identity; None with too few degrees of freedom or noisy columns."""
    R, dof = within_object_residuals(np.asarray(Z, dtype=np.float64), objects)
    n_objects = R.shape[0] - dof
    if dof < max(MIN_NOISE_DOF, n_objects) or R.shape[1] < min_columns:
        return None
    var = (R**2).sum(axis=0) / dof
    noisy = var > 1e-24 * np.maximum(1.0, np.abs(Z).max(axis=0) ** 2)
    if noisy.sum() < min_columns:
        return None
    sd = np.sqrt(var[noisy])
    U = R[:, noisy] / sd
    if shrinkage is None:
        # Imported here: the command line reads this module's settings without scikit-learn.
        from sklearn.covariance import ledoit_wolf_shrinkage

        # The residuals are centred per object: Ledoit-Wolf's intensity for centred data.
        shrinkage = ledoit_wolf_shrinkage(U, assume_centered=True) if U.shape[1] > 1 else 0.0
    corr = (1.0 - shrinkage) * (U.T @ U / dof) + shrinkage * np.eye(U.shape[1])
    vals, vecs = np.linalg.eigh(corr)
    floor = 1e-12 * vals.max()
    inv_sqrt = vecs @ np.diag(1.0 / np.sqrt(np.maximum(vals, floor))) @ vecs.T
    W = np.eye(Z.shape[1])
    idx = np.flatnonzero(noisy)
    W[np.ix_(idx, idx)] = inv_sqrt / sd[None, :]
    return W


#: The transforms of this skin's modalities, for features this package extracted from the
#: skin's recordings (its data sets, the simulated world): texture columns 0-2 are the Hjorth
#: activities (variances); the other modalities are z-scored as they are. Another sensor's
#: table whose groups happen to share these names gets :data:`GENERIC_TRANSFORMS`.
SKIN_TRANSFORMS: Mapping[str, ModalityTransform] = {
    "force": ModalityTransform(),
    "texture": ModalityTransform(log_columns=(0, 1, 2)),
    "thermal": ModalityTransform(pca_components=10),
}


#: Every modality z-scored as it is: for feature tables (any sensor's features).
GENERIC_TRANSFORMS: Mapping[str, ModalityTransform] = {}

#: The name of this package's extraction of this skin's features: what ``aptkt dataset
#: export-features`` writes in a feature table's ``extraction`` column.
SKIN_EXTRACTION = "aptkt-skin"
#: Whose features a table holds, as the command line asks: "auto" (the table's ``extraction``
#: column says), this skin's as this package extracts them, or any other sensor's.
EXTRACTIONS = ("auto", SKIN_EXTRACTION, "other")


def transforms_of(extraction: str | None, asked: str = "auto") -> Mapping[str, ModalityTransform]:
    """The transforms of features computed by ``extraction`` (a table's ``extraction``
    column, :attr:`Observations.extraction`): this skin's (:data:`SKIN_TRANSFORMS`) for
    :data:`SKIN_EXTRACTION` — as ``extraction`` says when ``asked`` is "auto", or as asked —
    and :data:`GENERIC_TRANSFORMS` for any other features, whatever their modalities are
    called."""
    if asked not in EXTRACTIONS:
        raise ConfigError(f"extraction must be one of {EXTRACTIONS}, got {asked!r}")
    extraction = extraction if asked == "auto" else asked
    return SKIN_TRANSFORMS if extraction == SKIN_EXTRACTION else GENERIC_TRANSFORMS


class FeaturePipeline:
    """Per-modality transforms for one action; modalities without a configured transform are
    z-scored. ``transforms`` None: as the observations it is fitted on were computed
    (:func:`transforms_of` their ``extraction``): this skin's (:data:`SKIN_TRANSFORMS`) for
    this package's extraction of the skin, none beyond z-scoring for any other features."""

    def __init__(self, transforms: Mapping[str, ModalityTransform] | None = None) -> None:
        self._given = transforms
        self.transforms: dict[str, ModalityTransform] = {
            k: replace(v) for k, v in (transforms or {}).items()
        }
        self.modality_names_: tuple[str, ...] = ()
        #: With ``scale="whiten-joint"``: the map applied to the modalities' outputs side by
        #: side (:func:`joint_noise_whitener`); None otherwise.
        self.joint_: np.ndarray | None = None

    def fit(self, obs: Observations, *, scale: str = "spread") -> FeaturePipeline:
        """Fit on training observations (never on test data). ``scale``
        (:data:`FEATURE_SCALES`): the metric — each column by its spread over the observations,
        or the noise between repeated observations of the same object, whitened per modality
        ("whiten") or then across the modalities too ("whiten-joint")."""
        if scale not in FEATURE_SCALES:
            raise InvalidInputError(f"scale must be one of {FEATURE_SCALES}, got {scale!r}")
        whiten = scale in ("whiten", "whiten-joint")
        objects = obs.objects if whiten else None
        templates = self._given if self._given is not None else transforms_of(obs.extraction)
        fitted = {}
        for name in obs.modality_names:
            template = templates.get(name, ModalityTransform())
            fitted[name] = replace(template, mean_=None, scale_=None, components_=None).fit(
                obs.modalities[name], objects, whiten=whiten
            )
        self.transforms = fitted
        self.modality_names_ = obs.modality_names
        self.joint_ = None
        if scale == "whiten-joint":
            self.joint_ = joint_noise_whitener(self.transform(obs)[0], obs.objects)
        return self

    def transform(self, obs: Observations) -> tuple[np.ndarray, dict[str, list[int]]]:
        """Feature matrix and the column group of each modality (for the multi-modal kernel)."""
        if not self.modality_names_:
            raise InvalidStateError("FeaturePipeline is not fitted")
        if obs.modality_names != self.modality_names_:
            raise InvalidInputError(
                f"action {obs.action!r}: observations have modalities {obs.modality_names}, "
                f"the pipeline was fitted on {self.modality_names_}"
            )
        blocks, groups, start = [], {}, 0
        for name in self.modality_names_:
            block = self.transforms[name].transform(obs.modalities[name])
            blocks.append(block)
            groups[name] = list(range(start, start + block.shape[1]))
            start += block.shape[1]
        X = np.hstack(blocks)
        if self.joint_ is not None:
            X = X @ self.joint_.T
        return X, groups

    def state(self, prefix: str) -> dict[str, np.ndarray]:
        out: dict[str, np.ndarray] = {
            f"{prefix}/modalities": np.asarray(self.modality_names_, dtype="U")
        }
        for name in self.modality_names_:
            for key, value in self.transforms[name].state().items():
                out[f"{prefix}/{name}/{key}"] = value
        if self.joint_ is not None:
            out[f"{prefix}/joint"] = self.joint_
        return out

    @classmethod
    def from_state(cls, arrays: Mapping[str, Any], prefix: str) -> FeaturePipeline:
        pipe = cls({})
        names = tuple(str(n) for n in np.asarray(arrays[f"{prefix}/modalities"]))
        transforms = {}
        for name in names:
            sub = {
                key[len(f"{prefix}/{name}/") :]: arrays[key]
                for key in arrays
                if key.startswith(f"{prefix}/{name}/")
            }
            transforms[name] = ModalityTransform.from_state(sub)
        pipe.transforms = transforms
        pipe.modality_names_ = names
        # Files written before the joint whitening existed have no such member.
        joint = arrays.get(f"{prefix}/joint")
        pipe.joint_ = None if joint is None else np.asarray(joint, dtype=np.float64)
        return pipe
