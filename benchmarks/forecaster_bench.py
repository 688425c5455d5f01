"""Forecaster speed: forward and training-step time per solver, and one-forecast latency.

Batch 32, 16 steps, 25 features, 128 units, 6 ODE unfolds per step (the shipped setting), CPU.
Prints figures; asserts nothing.
"""
from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

import torch

from oilspill_moos.forecaster.models import KINDS, build_model
from oilspill_moos.forecaster.train import forecast_loss


def timed(fn, repeats: int) -> float:
    fn()
    samples = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        samples.append(time.perf_counter() - start)
    return 1e3 * statistics.median(samples)


def bench_model(kind: str, adaptive: bool = False, repeats: int = 10) -> dict[str, float]:
    torch.manual_seed(0)
    model = build_model(kind, n_features=25, n_targets=6, hidden=128, unfolds=6, adaptive=adaptive)
    x, dt, y = torch.randn(32, 16, 25), torch.ones(32, 16), torch.randn(32, 4, 6)
    optimiser = torch.optim.AdamW(model.parameters(), lr=1e-4)

    def forward():
        with torch.no_grad():
            model(x, dt)

    def train_step():
        mean, sigma = model(x, dt)
        loss, _ = forecast_loss(mean, sigma, y, alpha=0.1, beta=0.5, nll_weight=0.1, area_targets=(2,))
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()

    def one_forecast():
        with torch.no_grad():
            model(x[:1], dt[:1])

    model.eval()
    result = {"forward_ms": timed(forward, repeats), "latency_ms": timed(one_forecast, 3 * repeats)}
    model.train()
    result["train_step_ms"] = timed(train_step, repeats)
    return result


def shipped_latency() -> str:
    """End-to-end latency of the operational path (features, window, model, polygon) if weights exist."""
    weights = Path(__file__).resolve().parents[1] / "oilspill_moos" / "forecaster" / "weights" / "ltc-rk4.pt"
    if not weights.exists():
        return "shipped weights not found: end-to-end latency skipped"
    from oilspill_moos.forecaster.dataset import load_dataset
    from oilspill_moos.forecaster.operational import Forecaster

    forecaster = Forecaster(weights.parent, "ltc-rk4")
    scenario = load_dataset()[0]
    geoms, times, envs = scenario.geometries[:24], scenario.times()[:24], scenario.environments()[:24]
    ms = timed(lambda: forecaster.forecast(geoms, times, envs, scenario.release_time), 5)
    return f"end-to-end forecast (24 observations -> 4 boundary polygons, ltc-rk4): {ms:.1f} ms"


def main() -> int:
    torch.set_num_threads(1)
    print(f"forecaster benchmark: batch 32, 16 steps, 25 features, 128 units, 6 unfolds, 1 CPU thread "
          f"(torch {torch.__version__})")
    print(f"{'model':<22}{'forward ms':>12}{'train step ms':>15}{'1 forecast ms':>15}")
    rows = [(kind, False) for kind in KINDS] + [("ltc-fused", True)]
    for kind, adaptive in rows:
        r = bench_model(kind, adaptive)
        label = kind + (" (adaptive)" if adaptive else "")
        print(f"{label:<22}{r['forward_ms']:>12.1f}{r['train_step_ms']:>15.1f}{r['latency_ms']:>15.2f}")
    print(shipped_latency())
    return 0


if __name__ == "__main__":
    sys.exit(main())
