"""Learning tactual properties of new objects with prior tactile knowledge (paper §4).

=====================  =====================================================================
observations           feature observations as plain arrays (any sensor)
pipeline               per-modality transforms (scaling, log, thermal PCA) fitted on training
prior                  prior knowledge: old objects' observations, pipelines, models; save/load
kernel                 the new objects' kernel: amplitude from the task, length-scale from every label
identity               which known object, or none: the library's generative model of its objects
transfer               from where and how much to transfer (Eq. 3)
transfer_summary       transfer decisions in words: the old object learned from, or why not
evidence               Laplace evidence of a fitted classifier's labels, given its source task
library                a library that grows: prior knowledge merged from several files
recognition            recognise touches with a library, and flag objects it does not hold
active                 uncertainty and next (action, object) selection (Eq. 4)
learner                the APTKT process and the baseline
estimator              APTKTClassifier: a scikit-learn classifier that learns with a library
environment            where observations come from (pools; robots through aptkt.actions.executor)
evaluation             accuracy on held-out test observations, fused over actions
=====================  =====================================================================
"""

from typing import TYPE_CHECKING

from aptkt._lazy import lazy_exports

# Each name loads its module on first use (aptkt._lazy): the command line imports only the
# settings of this package.
if TYPE_CHECKING:
    from aptkt.learning.config import GPSettings, LearnerConfig
    from aptkt.learning.environment import Environment, PoolEnvironment, PoolExhaustedError
    from aptkt.learning.estimator import APTKTClassifier
    from aptkt.learning.identity import ObjectIdentity
    from aptkt.learning.learner import APTKT, LearningRun, StepRecord
    from aptkt.learning.library import merge_priors
    from aptkt.learning.observations import Observations, ObservationTable
    from aptkt.learning.pipeline import FeaturePipeline, ModalityTransform
    from aptkt.learning.prior import ActionPrior, PriorKnowledge
    from aptkt.learning.recognition import Recognition
    from aptkt.learning.transfer import TransferDecision, decide_transfer
else:
    __getattr__, __dir__ = lazy_exports(__name__, __file__)


__all__ = [
    "APTKT",
    "APTKTClassifier",
    "ActionPrior",
    "Environment",
    "FeaturePipeline",
    "GPSettings",
    "LearnerConfig",
    "LearningRun",
    "ModalityTransform",
    "ObjectIdentity",
    "Observations",
    "ObservationTable",
    "PoolEnvironment",
    "PoolExhaustedError",
    "PriorKnowledge",
    "Recognition",
    "StepRecord",
    "TransferDecision",
    "decide_transfer",
    "merge_priors",
]
