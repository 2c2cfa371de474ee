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
gradients from several starts — per classifier, or one kernel shared by every classifier (and
by further labelled data sets, ``fit(..., kernel_tasks=...)``). The classifiers are fitted in
parallel in Rust with the GIL released. Models are saved with :meth:`LaplaceGPC.save` to a NumPy ``.npz`` file (no pickle).
"""

from typing import TYPE_CHECKING

from aptkt._lazy import lazy_exports

# Each name loads its module on first use (aptkt._lazy): the command line imports only the
# settings of this package.
if TYPE_CHECKING:
    from aptkt.errors import KernelNotPositiveDefiniteError
    from aptkt.gp.estimator import LaplaceGPC, uniform_class_prior
    from aptkt.gp.kernel import kernel_matrix
    from aptkt.gp.settings import (
        CLASS_PRIORS,
        DEFAULTS,
        KERNELS,
        LATENT_MEANS,
        MAX_ITERATIONS,
        MAX_RESTARTS,
        FitDefaults,
        HyperPrior,
        check_optimizer_tol,
    )
    from aptkt.gp.sources import TransferSource
else:
    __getattr__, __dir__ = lazy_exports(__name__, __file__)


__all__ = [
    "CLASS_PRIORS",
    "DEFAULTS",
    "FitDefaults",
    "HyperPrior",
    "KERNELS",
    "KernelNotPositiveDefiniteError",
    "LATENT_MEANS",
    "LaplaceGPC",
    "MAX_ITERATIONS",
    "MAX_RESTARTS",
    "TransferSource",
    "check_optimizer_tol",
    "kernel_matrix",
    "uniform_class_prior",
]
