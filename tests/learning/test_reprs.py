"""What the package's objects say they are: one short line with the facts a user looks for,
never an address and never an array's values."""

from __future__ import annotations

import numpy as np
import pytest

from aptkt.experiments.own_data import Comparison
from aptkt.learning import (
    LearnerConfig,
    LearningRun,
    Observations,
    PriorKnowledge,
    Recognition,
    StepRecord,
)
from aptkt.learning.recognition import Calibration


def _short(text: str) -> str:
    assert "object at 0x" not in text
    assert "array(" not in text and "\n" not in text
    assert len(text) < 300, text
    return text


@pytest.fixture(scope="module")
def library():
    rng = np.random.default_rng(0)
    objects = np.repeat(["old_a", "old_b", "old_c"], 6)
    obs = {
        a: Observations.from_arrays(
            a, objects, force=rng.normal(size=(18, 1)), heat=rng.normal(size=(18, 4))
        )
        for a in ("press", "slide")
    }
    return PriorKnowledge.build(obs, seed=0)


def test_prior_knowledge_says_its_objects_actions_columns_and_model(library):
    text = _short(repr(library))
    assert text.startswith("PriorKnowledge(3 objects, 2 actions: ")
    assert "press (18 observations; force 1, heat 4)" in text
    assert "slide (18 observations; force 1, heat 4)" in text
    assert "library model local" in text
    action = _short(repr(library["press"]))
    assert action == "ActionPrior('press': 3 objects, 18 observations, columns force 1, heat 4)"
    obs = _short(repr(library["press"].observations))
    assert obs == "Observations('press': 18 observations of 3 objects; columns force 1, heat 4)"


def test_a_large_library_lists_its_first_actions_only():
    rng = np.random.default_rng(1)
    objects = np.repeat(["a", "b"], 2)
    table = {
        f"act{k}": Observations.from_arrays(f"act{k}", objects, f=rng.normal(size=(4, 1)))
        for k in range(6)
    }
    text = _short(repr(PriorKnowledge.build(table, gp=None, seed=0)))
    assert "6 actions" in text and "act2" in text and "act3" not in text
    assert "... 3 more" in text


def _step(step, action=None, obj=None, accuracy=0.75):
    return StepRecord(
        step=step,
        n_observations=6 + step,
        action=action,
        object=obj,
        explored=step == 2,
        uncertainty=0.3,
        accuracy={"press": accuracy},
        mean_accuracy=accuracy,
        fused_accuracy=accuracy,
        transfer={"press": {"new_a": {"source": "old_a", "lambda": 0.8}}},
        seconds=0.125,
        hyperparameters={"press": {"new_a": {"signal_variance": 2.0}}},
    )


def test_a_step_says_what_was_observed_and_how_well_the_models_did():
    assert _short(repr(_step(0))) == (
        "StepRecord(step 0: initial round; 6 observations, mean accuracy 0.750, fused 0.750, "
        "0.12 s)"
    )
    text = _short(repr(_step(2, "press", "new_b", 0.875)))
    assert text.startswith("StepRecord(step 2: press on new_b (explored); 8 observations")
    assert "mean accuracy 0.875" in text


def test_a_run_says_its_method_objects_steps_and_final_accuracy():
    run = LearningRun(
        LearnerConfig(transfer="paper"),
        ["press", "slide"],
        ["new_a", "new_b", "new_c"],
        ["old_a", "old_b"],
        [_step(0), _step(1, "press", "new_a"), _step(2, "slide", "new_c", 0.9)],
        stopped_early=True,
    )
    text = _short(repr(run))
    for fact in (
        "transfer 'paper'",
        "3 new objects",
        "2 prior objects",
        "actions press, slide",
        "3 steps, stopped early",
        "final mean accuracy 0.900 after 8 observations",
    ):
        assert fact in text
    empty = LearningRun(LearnerConfig(transfer="none"), ["press"], ["a", "b"], [])
    assert _short(repr(empty)).endswith("0 steps)")


def test_a_recognition_says_its_touches_library_and_accuracy():
    result = Recognition(
        library=["o0", "o1", "o2"],
        calibration=Calibration(
            threshold=1.0, false_alarm_rate=0.05, detection_rate=0.9, touches=40
        ),
        object=["o0", "o1", "u0", "o1"],
        trial=[0, 0, 0, 1],
        actions=["A"] * 4,
        predicted=["o0", "o2", "o1", "o1"],
        probability=np.full(4, 0.9),
        runner_up=["o1", "o1", "o0", "o0"],
        novelty=np.array([-3.0, -2.0, 4.0, -1.0]),
        known=np.array([True, True, False, True]),
    )
    text = _short(repr(result))
    assert text == (
        "Recognition(4 touches of 3 objects; library of 3 objects; 1 flagged new; "
        "accuracy 0.667 on the library's objects; false-alarm rate 0.05)"
    )


def test_a_comparison_on_own_data_says_its_objects_runs_and_final_accuracies(tmp_path):
    curves = {
        m: np.tile(np.linspace(0.5, v, 7), (3, 1)) for m, v in (("APTKT", 0.9), ("baseline", 0.8))
    }
    result = Comparison(
        accuracy=curves,
        fused_accuracy=curves,
        prior_objects=("old_a", "old_b"),
        new_objects=("new_a", "new_b", "new_c"),
        actions=["press"],
        rows=[{"step": k} for k in range(42)],
        output=tmp_path,
    )
    text = _short(repr(result))
    for fact in (
        "3 new objects, 2 prior objects",
        "actions press",
        "3 runs of 7 steps",
        "final accuracy APTKT 0.900, baseline 0.800",
        f"files in {tmp_path}",
    ):
        assert fact in text
