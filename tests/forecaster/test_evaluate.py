"""Evaluation: scenario-level statistics with known answers, and the scoring pipeline on stored scenarios."""
import math

import numpy as np
import pytest

from oilspill_moos.forecaster import engine as E
from oilspill_moos.forecaster import evaluate as V
from oilspill_moos.forecaster.dataset import GULF_STEM, load_dataset, split_scenarios


def test_bootstrap_and_paired_intervals():
    mean, lo, hi = V.bootstrap_ci(np.arange(10.0))
    assert mean == 4.5 and lo < 4.5 < hi and hi - lo < 5
    a = np.array([0.5, 0.6, 0.7, 0.8])
    verdict, (diff, lo, hi) = V.compare(a + 0.1, a, higher_is_better=True, seed=0)
    assert verdict == "better" and diff == pytest.approx(0.1) and lo == pytest.approx(0.1)
    assert V.compare(a, a + 0.1, higher_is_better=True, seed=0)[0] == "worse"
    assert V.compare(a + 1.0, a, higher_is_better=False, seed=0)[0] == "worse"
    noisy = np.array([0.1, -0.1, 0.2, -0.2])
    assert V.compare(a + noisy, a, higher_is_better=True, seed=0)[0] == "not significantly different"


def test_coverage_of_exact_gaussian_errors_is_nominal():
    rng = np.random.default_rng(0)
    errors = np.linalg.norm(rng.normal(0, 1, (20_000, 1, 2)), axis=-1)       # uncertainty_m = 1 exactly
    scores = V.Scores(["k"], (3,), np.zeros(20_000), np.zeros(20_000), normalised={"k": errors})
    for level in V.COVERAGE_LEVELS:
        assert V.coverage(scores, "k", level)[0] == pytest.approx(level, abs=0.01)


def test_scoring_pipeline_on_held_out_scenarios():
    test = split_scenarios(load_dataset(GULF_STEM)).test[:2]
    scores = V.score(test, ["persistence", "physics"], E.Settings(), {}, stride=12, progress=False)
    n = len(scores.scenario)
    assert n >= 2 and set(scores.scenario) == {s.scenario_id for s in test}
    for kind in ("persistence", "physics"):
        assert scores.iou[kind].shape == (n, 4) and np.all((0 <= scores.iou[kind]) & (scores.iou[kind] <= 1))
        assert np.all(scores.centroid_km[kind] >= 0)
    # persistence loses skill with the horizon
    assert scores.iou["persistence"][:, 0].mean() > scores.iou["persistence"][:, -1].mean()
    lines = V.metric_table(scores, "iou", 3, seed=0)
    assert len(lines) == 4 and lines[2].startswith("| persistence |")
    assert not math.isnan(V.paired_ci(scores.per_scenario("iou", "physics")[:, 0],
                                       scores.per_scenario("iou", "persistence")[:, 0])[0])


def test_split_line_says_when_the_weights_were_trained_on_an_earlier_set():
    split = {"train": ["a", "b", "c"], "val": ["d"], "test": ["t1", "t2"]}
    assert V.split_line(split, split, 2) == ("Split: 3 training, 1 validation (early stopping and calibration) "
                                           "and 2 test scenarios.")
    assert V.split_line(split, {}, 2) == V.split_line(split, split, 2)
    earlier = V.split_line(split, {"train": ["a"], "val": ["d"], "test": ["t1", "t2"]}, 2)
    assert earlier.endswith("The shipped weights were trained on 1 training and 1 validation scenarios of an earlier, "
                            "smaller set (their checkpoints record which); the test scenarios are the same, never "
                            "trained on.")
