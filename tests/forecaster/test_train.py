"""Training reduces the loss on a tiny learnable set; checkpoints round-trip; the paper's settings apply."""
import pytest
import torch

from oilspill_moos.forecaster.train import (SOLVER_DEFAULTS, TrainConfig, WindowTensors, fit, forecast_loss,
                                            load_checkpoint)


def tiny_set(n: int, seed: int) -> WindowTensors:
    """Targets are a fixed linear read-out of the last step, so a few epochs must learn something."""
    g = torch.Generator().manual_seed(seed)
    x = torch.randn(n, 16, 25, generator=g)
    mix = torch.linspace(-1, 1, 25 * 4 * 3).view(25, 4, 3)
    y = torch.einsum("nf,fhk->nhk", x[:, -1], mix) / 5.0
    return WindowTensors(x, torch.ones(n, 16), y)


@pytest.mark.parametrize("kind", ["ltc-fused", "lstm"])
def test_training_reduces_the_loss_and_checkpoint_round_trips(kind, tmp_path):
    cfg = TrainConfig(kind=kind, epochs=6, batch_size=16, hidden=16, unfolds=1, lr=1e-2, seed=3,
                      area_targets=(0,))
    train, val = tiny_set(96, 0), tiny_set(32, 1)
    model, history = fit(train, val, cfg, checkpoint=tmp_path / "m.pt", progress=False)
    assert history[-1]["train_loss"] < 0.7 * history[0]["train_loss"]
    loaded, blob = load_checkpoint(tmp_path / "m.pt")
    assert blob["train_config"]["kind"] == kind
    with torch.no_grad():
        assert torch.allclose(loaded(val.x, val.dt)[0], model(val.x, val.dt)[0])


def test_paper_settings_per_solver():
    assert TrainConfig(kind="ltc-rk4").lr == 3e-4 and TrainConfig(kind="ltc-rk4").alpha == 0.05
    assert TrainConfig(kind="ltc-fused").lr == 5e-4 and TrainConfig(kind="ltc-fused").alpha == 0.1
    assert TrainConfig(kind="ltc-euler").lr == 1e-3 and TrainConfig(kind="ltc-euler").alpha == 0.2
    assert set(SOLVER_DEFAULTS) == {"ltc-rk4", "ltc-fused", "ltc-euler", "lstm"}
    with pytest.raises(ValueError, match="--model"):
        TrainConfig(kind="gru")


def test_loss_terms():
    target = torch.zeros(2, 4, 3)
    mean = torch.arange(4.0).view(1, 4, 1).expand(2, 4, 3)
    total, parts = forecast_loss(mean, torch.ones_like(mean), target, alpha=0.5, beta=2.0, nll_weight=0.0,
                                 area_targets=(0,))
    assert parts["mse"] == pytest.approx((0 + 1 + 4 + 9) / 4)
    assert parts["smooth"] == pytest.approx(3.0)          # each step of 1 in 3 columns
    assert parts["area"] == pytest.approx(parts["mse"])
    assert total.item() == pytest.approx(3.5 + 0.5 * 3.0 + 2.0 * 3.5)


def test_mismatched_or_empty_windows_are_refused():
    with pytest.raises(ValueError, match="disagree"):
        WindowTensors(torch.zeros(3, 16, 25), torch.zeros(2, 16), torch.zeros(3, 4, 2))
    with pytest.raises(ValueError, match="no windows"):
        WindowTensors(torch.zeros(0, 16, 25), torch.zeros(0, 16), torch.zeros(0, 4, 2))
