"""Training reduces the loss on a tiny learnable set; checkpoints round-trip; the paper's settings apply."""
import numpy as np
import pytest
import torch

from oilspill_moos.forecaster.models import load_checkpoint
from oilspill_moos.forecaster.engine import RADIUS_95
from oilspill_moos.forecaster.train import (SOLVER_DEFAULTS, TrainConfig, WindowTensors, conformal_quantile, fit,
                                           forecast_loss, groupwise_factors)


def tiny_set(n: int, seed: int) -> WindowTensors:
    """Targets are a fixed linear read-out of the last step, so a few epochs must learn something."""
    g = torch.Generator().manual_seed(seed)
    x = torch.randn(n, 16, 25, generator=g)
    mix = torch.linspace(-1, 1, 25 * 4 * 3).view(25, 4, 3)
    y = torch.einsum("nf,fhk->nhk", x[:, -1], mix) / 5.0
    return WindowTensors(x, torch.ones(n, 16), y)


@pytest.mark.parametrize("kind", ["ltc-fused", "lstm"])
def test_training_reduces_the_loss_and_checkpoint_round_trips(kind, tmp_path):
    cfg = TrainConfig(kind=kind, epochs=6, batch_size=16, hidden=16, unfolds=1, lr=1e-2, seed=3)
    train, val = tiny_set(96, 0), tiny_set(32, 1)
    model, history = fit(train, val, cfg, checkpoint=tmp_path / "m.pt", progress=False)
    assert history[-1]["train_loss"] < 0.7 * history[0]["train_loss"]
    loaded, blob = load_checkpoint(tmp_path / "m.pt")
    assert blob["train_config"]["kind"] == kind
    with torch.no_grad():
        assert torch.allclose(loaded(val.x, val.dt)[0], model(val.x, val.dt)[0])


def test_settings_per_solver():
    assert {k: TrainConfig(kind=k).lr for k in SOLVER_DEFAULTS} == {k: v[0] for k, v in SOLVER_DEFAULTS.items()}
    assert set(SOLVER_DEFAULTS) == {"ltc-rk4", "ltc-fused", "ltc-euler", "lstm"}
    with pytest.raises(ValueError, match="--model"):
        TrainConfig(kind="gru")


def test_loss_terms():
    target = torch.zeros(2, 4, 3)
    mean = torch.arange(4.0).view(1, 4, 1).expand(2, 4, 3)
    total, parts = forecast_loss(mean, torch.ones_like(mean), target, nll_weight=0.5)
    assert parts["mse"] == pytest.approx((0 + 1 + 4 + 9) / 4)
    assert parts["nll"] == pytest.approx(0.5 * parts["mse"])          # unit sigma: NLL = squared error / 2
    assert total.item() == pytest.approx(parts["mse"] + 0.5 * parts["nll"])


def test_mismatched_or_empty_windows_are_refused():
    with pytest.raises(ValueError, match="disagree"):
        WindowTensors(torch.zeros(3, 16, 25), torch.zeros(2, 16), torch.zeros(3, 4, 2))
    with pytest.raises(ValueError, match="no windows"):
        WindowTensors(torch.zeros(0, 16, 25), torch.zeros(0, 16), torch.zeros(0, 4, 2))


def test_conformal_quantile_holds_a_new_case_with_the_promised_probability():
    """Split conformal: of n exchangeable scores, the ceil((n + 1) p)-th smallest bounds a new one with
    probability >= p. Known answers on small sets, and the coverage on fresh draws."""
    assert conformal_quantile(np.arange(1.0, 20.0), 0.95) == 19.0          # n = 19: the 19th (largest)
    assert conformal_quantile(np.arange(1.0, 40.0), 0.95) == 38.0          # n = 39: ceil(38) = 38th
    rng = np.random.default_rng(0)
    hits = [rng.rayleigh() <= conformal_quantile(rng.rayleigh(size=50), 0.95) for _ in range(4000)]
    assert 0.95 <= np.mean(hits) <= 0.975


def test_groupwise_factors_cover_each_group_where_a_pooled_factor_under_covers_the_harder_one():
    """Known answer: validation errors of an easy group (scale 1) and a hard one (scale 3). A factor
    pooled over both covers the hard group's new cases well under 95 %; the group-wise factor (the
    largest of the groups' conformal quantiles) covers each group at 95 % or more."""
    rng = np.random.default_rng(1)
    ratios = np.concatenate([rng.rayleigh(1.0, size=(200, 2)), rng.rayleigh(3.0, size=(200, 2))])
    labels = np.array(["steady"] * 200 + ["varying"] * 200)
    pooled = groupwise_factors(ratios, np.zeros(400))
    grouped = groupwise_factors(ratios, labels)
    assert grouped[0] == pytest.approx(conformal_quantile(ratios[200:, 0], 0.95) / RADIUS_95)
    hard = rng.rayleigh(3.0, size=20000)
    assert np.mean(hard <= pooled[0] * RADIUS_95) < 0.92
    for scale in (1.0, 3.0):
        assert np.mean(rng.rayleigh(scale, size=20000) <= grouped[1] * RADIUS_95) >= 0.93


def test_examples_and_fits_over_worker_processes_equal_the_serial_ones(tmp_path):
    """`train --workers` spreads examples and models over processes; the results must not depend on it."""
    from oilspill_moos.forecaster import dataset as D
    from oilspill_moos.forecaster.physics import DriftParameters
    from oilspill_moos.forecaster.train import _train_job, build_examples, mapped

    scenarios = sorted(D.load_dataset(D.GULF_STEM), key=len)[:2]
    serial = build_examples(scenarios, DriftParameters(), 2, progress=False, workers=1)
    parallel = build_examples(scenarios, DriftParameters(), 2, progress=False, workers=2)
    assert len(serial.x) > 0 and serial.scenario == parallel.scenario
    for a, b in ((serial.x, parallel.x), (serial.dt, parallel.dt), (serial.y, parallel.y)):
        np.testing.assert_array_equal(a, b)
    cfg = TrainConfig(kind="lstm", epochs=2, batch_size=16, hidden=8, unfolds=1, seed=3)
    jobs = [(tiny_set(48, 0), tiny_set(16, 1), cfg, tmp_path / f"{n}.pt", None, False, 0) for n in range(2)]
    one, two = list(mapped(_train_job, jobs, 2))
    alone = _train_job(jobs[0])
    assert one["val_at_best"] == two["val_at_best"] == alone["val_at_best"]

