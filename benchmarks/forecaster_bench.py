"""Forecaster speed: one whole forecast per kind (16 hourly observations -> 4 horizons, ensemble and
both contours included), CPU time on one thread; and each network's forward and training step.

Prints figures; asserts nothing. The goal is <= 50 ms per forecast on one core.
"""
from __future__ import annotations

import statistics
import sys
import time

import torch

from oilspill_moos.forecaster import features as F
from oilspill_moos.forecaster.dataset import load_dataset
from oilspill_moos.forecaster.kinds import KINDS, LEARNED_KINDS
from oilspill_moos.forecaster.models import build_model
from oilspill_moos.forecaster.operational import WEIGHTS_DIR, Forecaster
from oilspill_moos.forecaster.train import TrainConfig, forecast_loss


def cpu_ms(fn, repeats: int) -> float:
    """Median CPU milliseconds of ``fn`` (CPU time: the machine is shared, wall time would measure the others)."""
    fn()
    samples = []
    for _ in range(repeats):
        start = time.process_time()
        fn()
        samples.append(time.process_time() - start)
    return 1e3 * statistics.median(samples)


def bench_network(kind: str, repeats: int = 10) -> tuple[float, float]:
    torch.manual_seed(0)
    cfg = TrainConfig(kind=kind)
    model = build_model(kind, n_features=len(F.FEATURE_NAMES), hidden=cfg.hidden, unfolds=cfg.unfolds)
    x, dt, y = torch.randn(64, 16, len(F.FEATURE_NAMES)), torch.ones(64, 16), torch.randn(64, 4, 3)
    optimiser = torch.optim.AdamW(model.parameters(), lr=1e-4)

    def train_step():
        mean, sigma = model(x, dt)
        loss, _ = forecast_loss(mean, sigma, y, nll_weight=0.1)
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()

    def forward():
        with torch.no_grad():
            model(x[:1], dt[:1])

    return cpu_ms(forward, 3 * repeats), cpu_ms(train_step, repeats)


def main() -> int:
    torch.set_num_threads(1)
    scenario = next(s for s in load_dataset() if len(s) >= 16)
    args = (scenario.geometries[:16], scenario.times()[:16], scenario.environments()[:16])
    print(f"forecaster benchmark: one forecast from 16 hourly observations, 4 horizons, ensemble + 50/90 % "
          f"contours, CPU ms on 1 thread (torch {torch.__version__})")
    print(f"{'kind':<26}{'forecast ms':>12}{'net forward ms':>16}{'train step ms (batch 64)':>26}")
    for kind in KINDS:
        try:
            forecaster = Forecaster(WEIGHTS_DIR, kind)
        except FileNotFoundError as exc:
            print(f"{kind:<26} skipped: {exc}")
            continue
        ms = cpu_ms(lambda: forecaster.forecast(*args), 10)
        net = bench_network(kind) if kind in LEARNED_KINDS else None
        extra = f"{net[0]:>16.1f}{net[1]:>26.1f}" if net else ""
        print(f"{kind:<26}{ms:>12.1f}{extra}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
