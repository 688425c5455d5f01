"""Training of the forecasters: the paper's loss, AdamW with solver-specific settings, early stopping.

Loss (paper, "Training Strategy and Loss Function"):
    L = MSE + alpha * smoothness + beta * area
with smoothness = mean ||y_pred[h+1] - y_pred[h]||^2 over consecutive horizons and the area term
an extra MSE on the area-related target columns. The uncertainty head needs a signal of its own
and the paper gives none: it is trained by a Gaussian negative log-likelihood on the *detached*
mean, so it never changes what the mean head learns from the paper's loss.
"""
from __future__ import annotations

import copy
import random
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch
from torch import nn
from tqdm import tqdm

from .models import KINDS, ModelConfig, SpillForecaster

# kind -> (learning rate, alpha, early-stopping patience in epochs). LTC values are the paper's;
# the paper gives none for the LSTM, which gets Euler's rate (its typical Adam regime) and alpha 0.1.
SOLVER_DEFAULTS = {
    "ltc-rk4": (3e-4, 0.05, 12),
    "ltc-fused": (5e-4, 0.1, 10),
    "ltc-euler": (1e-3, 0.2, 8),
    "lstm": (1e-3, 0.1, 8),
}


@dataclass
class WindowTensors:
    """Model-ready windows: x [N, T, F] scaled, dt [N, T] hours, y [N, H, K] scaled targets."""

    x: torch.Tensor
    dt: torch.Tensor
    y: torch.Tensor

    def __post_init__(self):
        self.x, self.dt, self.y = (torch.as_tensor(np.asarray(a), dtype=torch.float32)
                                   for a in (self.x, self.dt, self.y))
        if not (len(self.x) == len(self.dt) == len(self.y)):
            raise ValueError(f"window arrays disagree in length: {len(self.x)}, {len(self.dt)}, {len(self.y)}")
        if len(self.x) == 0:
            raise ValueError("no windows to train or evaluate on")

    def __len__(self) -> int:
        return len(self.x)


@dataclass
class TrainConfig:
    kind: str = "ltc-rk4"
    epochs: int = 40
    batch_size: int = 32
    lr: float | None = None            # None: SOLVER_DEFAULTS
    alpha: float | None = None         # smoothness weight; None: SOLVER_DEFAULTS
    beta: float = 0.5                  # extra weight on the area targets
    nll_weight: float = 0.1            # uncertainty head (detached mean)
    weight_decay: float = 1e-2
    patience: int | None = None        # None: SOLVER_DEFAULTS
    seed: int = 0
    hidden: int = 128
    unfolds: int = 6
    adaptive: bool = False
    grad_clip: float = 1.0
    threads: int = 1
    max_seconds: float | None = None   # wall-clock cap; training stops after the epoch that passes it
    area_targets: tuple[int, ...] = field(default_factory=tuple)

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"--model must be one of {KINDS}, not {self.kind!r}")
        lr, alpha, patience = SOLVER_DEFAULTS[self.kind]
        self.lr = lr if self.lr is None else self.lr
        self.alpha = alpha if self.alpha is None else self.alpha
        self.patience = patience if self.patience is None else self.patience


def seed_everything(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)


def forecast_loss(mean, sigma, target, *, alpha: float, beta: float, nll_weight: float,
                  area_targets=()) -> tuple[torch.Tensor, dict[str, float]]:
    mse = nn.functional.mse_loss(mean, target)
    smooth = (mean[:, 1:] - mean[:, :-1]).pow(2).sum(-1).mean() if mean.shape[1] > 1 else mean.new_zeros(())
    area = (nn.functional.mse_loss(mean[..., list(area_targets)], target[..., list(area_targets)])
            if area_targets else mean.new_zeros(()))
    nll = nn.functional.gaussian_nll_loss(mean.detach(), target, sigma.pow(2))
    total = mse + alpha * smooth + beta * area + nll_weight * nll
    return total, {"loss": total.item(), "mse": mse.item(), "smooth": smooth.item(), "area": area.item(),
                   "nll": nll.item()}


def model_config_for(cfg: TrainConfig, n_features: int, n_targets: int, horizons_h) -> ModelConfig:
    return ModelConfig(kind=cfg.kind, n_features=n_features, n_targets=n_targets,
                       horizons_h=tuple(horizons_h), hidden=cfg.hidden, unfolds=cfg.unfolds,
                       adaptive=cfg.adaptive)


@torch.no_grad()
def evaluate_loss(model: SpillForecaster, data: WindowTensors, cfg: TrainConfig, batch: int = 256) -> dict:
    model.eval()
    sums: dict[str, float] = {}
    for start in range(0, len(data), batch):
        sl = slice(start, start + batch)
        mean, sigma = model(data.x[sl], data.dt[sl])
        _, parts = forecast_loss(mean, sigma, data.y[sl], alpha=cfg.alpha, beta=cfg.beta,
                                 nll_weight=cfg.nll_weight, area_targets=cfg.area_targets)
        n = len(data.x[sl])
        for key, value in parts.items():
            sums[key] = sums.get(key, 0.0) + value * n
    return {key: value / len(data) for key, value in sums.items()}


def fit(train: WindowTensors, val: WindowTensors, cfg: TrainConfig, horizons_h=(3, 7, 11, 15),
        checkpoint: Path | None = None, extra: dict | None = None, progress: bool = True):
    """Train one model; returns (best model, history). Best = lowest validation MSE+smoothness+area."""
    threads = torch.get_num_threads()
    torch.set_num_threads(cfg.threads)
    try:
        return _fit(train, val, cfg, horizons_h, checkpoint, extra, progress)
    finally:
        torch.set_num_threads(threads)


def _fit(train, val, cfg, horizons_h, checkpoint, extra, progress):
    seed_everything(cfg.seed)
    model = SpillForecaster(model_config_for(cfg, train.x.shape[-1], train.y.shape[-1], horizons_h))
    optimiser = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    generator = torch.Generator().manual_seed(cfg.seed)
    best_state, best_score, best_epoch, history = None, float("inf"), -1, []
    started = time.perf_counter()
    bar = tqdm(range(cfg.epochs), desc=cfg.kind, disable=not progress, leave=False)
    for epoch in bar:
        model.train()
        order = torch.randperm(len(train), generator=generator)
        running = 0.0
        for start in range(0, len(train), cfg.batch_size):
            idx = order[start:start + cfg.batch_size]
            mean, sigma = model(train.x[idx], train.dt[idx])
            loss, parts = forecast_loss(mean, sigma, train.y[idx], alpha=cfg.alpha, beta=cfg.beta,
                                        nll_weight=cfg.nll_weight, area_targets=cfg.area_targets)
            optimiser.zero_grad()
            loss.backward()
            nn.utils.clip_grad_norm_(model.parameters(), cfg.grad_clip)
            optimiser.step()
            running += parts["loss"] * len(idx)
        val_parts = evaluate_loss(model, val, cfg)
        score = val_parts["loss"] - cfg.nll_weight * val_parts["nll"]
        history.append({"epoch": epoch, "train_loss": running / len(train), "val": val_parts,
                         "seconds": time.perf_counter() - started})
        bar.set_postfix(train=f"{running / len(train):.4f}", val=f"{score:.4f}")
        if score < best_score:
            best_score, best_epoch, best_state = score, epoch, copy.deepcopy(model.state_dict())
            if checkpoint is not None:
                save_checkpoint(checkpoint, model, cfg, history, extra)
        if epoch - best_epoch >= cfg.patience:
            break
        if cfg.max_seconds is not None and time.perf_counter() - started > cfg.max_seconds:
            break
    model.load_state_dict(best_state)
    model.eval()
    return model, history


def save_checkpoint(path: Path, model: SpillForecaster, cfg: TrainConfig, history: list, extra: dict | None):
    """Weights, both configs, the history and caller extras (the scaler, data provenance) in one .pt."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    torch.save({"model_config": model.config.to_dict(), "train_config": asdict(cfg),
                "state_dict": {k: v.detach().clone() for k, v in model.state_dict().items()},
                "history": history, "extra": extra or {}}, path)


def load_checkpoint(path: Path) -> tuple[SpillForecaster, dict]:
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such checkpoint (run `python -m oilspill_moos.forecaster train`)")
    blob = torch.load(path, map_location="cpu", weights_only=False)
    model = SpillForecaster(ModelConfig.from_dict(blob["model_config"]))
    model.load_state_dict(blob["state_dict"])
    model.eval()
    return model, blob
