"""Training of the forecasters: the paper's loss, AdamW with solver-specific settings, early stopping.

Loss (paper, "Training Strategy and Loss Function"):
    L = MSE + alpha * smoothness + beta * area
with smoothness = mean ||y_pred[h+1] - y_pred[h]||^2 over consecutive horizons and the area term
an extra MSE on the area-related target columns. The uncertainty head needs a signal of its own
and the paper gives none: it is trained by a Gaussian negative log-likelihood on the *detached*
mean, so it never changes what the mean head learns from the paper's loss.
"""
from __future__ import annotations

import argparse
import copy
import hashlib
import json
import random
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch
from torch import nn
from tqdm import tqdm

from . import features as F
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
class DeltaScaler:
    """Targets as scaled changes from the last observed value, per horizon and target.

    The models forecast ``(y[h] - y_last - mean[h]) / std[h]``: zero is persistence, so the networks
    learn the spill's motion and growth, not its position in the Gulf, and no target is clipped.
    """

    mean: np.ndarray          # [H, K]
    std: np.ndarray           # [H, K]

    @classmethod
    def fit(cls, last: np.ndarray, targets: np.ndarray) -> "DeltaScaler":
        delta = np.asarray(targets, float) - np.asarray(last, float)[:, None, :]
        std = delta.std(axis=0)
        return cls(mean=delta.mean(axis=0), std=np.where(std > 1e-9, std, 1.0))

    def transform(self, last: np.ndarray, targets: np.ndarray) -> np.ndarray:
        return (np.asarray(targets, float) - np.asarray(last, float)[:, None, :] - self.mean) / self.std

    def inverse_transform(self, last: np.ndarray, scaled: np.ndarray) -> np.ndarray:
        return np.asarray(scaled, float) * self.std + self.mean + np.asarray(last, float)[:, None, :]

    def to_dict(self) -> dict:
        return {"mean": self.mean.tolist(), "std": self.std.tolist()}

    @classmethod
    def from_dict(cls, data: dict) -> "DeltaScaler":
        return cls(mean=np.asarray(data["mean"], float), std=np.asarray(data["std"], float))


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


# ---------------------------------------------------------------------------------------------------
# From scenarios to model-ready tensors

@dataclass
class Prepared:
    """Windows of one split with the scalers fitted on the training split."""

    windows: F.Windows
    tensors: WindowTensors
    scenario_ids: list[str]


def scenario_windows(scenarios, multipolygon: str = "largest") -> F.Windows:
    """Hourly 16-step windows (paper: hourly sequences over the first 48 h) of a list of scenarios."""
    return F.make_windows([s.sequence(multipolygon) for s in scenarios], scale="hourly")


def fit_scalers(train_windows: F.Windows) -> tuple[F.FeatureScaler, DeltaScaler]:
    feature_scaler = F.FeatureScaler.fit(train_windows.inputs)
    last = train_windows.inputs[:, -1, list(F.TARGET_INDICES)]
    return feature_scaler, DeltaScaler.fit(last, train_windows.targets)


def to_tensors(windows: F.Windows, feature_scaler: F.FeatureScaler, delta_scaler: DeltaScaler) -> WindowTensors:
    last = windows.inputs[:, -1, list(F.TARGET_INDICES)]
    return WindowTensors(feature_scaler.transform(windows.inputs), windows.elapsed_h,
                         delta_scaler.transform(last, windows.targets))


def prepare(scenarios, feature_scaler, delta_scaler, multipolygon="largest") -> Prepared:
    windows = scenario_windows(scenarios, multipolygon)
    return Prepared(windows, to_tensors(windows, feature_scaler, delta_scaler), [s.scenario_id for s in scenarios])


# ---------------------------------------------------------------------------------------------------
# The `train` command

WEIGHTS_DIR = Path(__file__).resolve().parent / "weights"


def file_sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def train_models(kinds, *, dataset_stem=None, out_dir: Path = WEIGHTS_DIR, split_seed: int = 0,
                 progress: bool = True, adaptive_fused: bool = False, **overrides) -> dict:
    """Train each kind on the same split and scalers; write ``<kind>.pt`` and ``metrics.json``."""
    from . import dataset as D

    scenarios = D.load_dataset(dataset_stem)
    split = D.split_scenarios(scenarios, seed=split_seed)
    train_windows = scenario_windows(split.train)
    feature_scaler, delta_scaler = fit_scalers(train_windows)
    train_t = to_tensors(train_windows, feature_scaler, delta_scaler)
    val_t = prepare(split.val, feature_scaler, delta_scaler).tensors
    stem = Path(dataset_stem) if dataset_stem is not None else D.DEFAULT_STEM
    extra = {"feature_scaler": feature_scaler.to_dict(), "delta_scaler": delta_scaler.to_dict(),
             "target_names": list(F.TARGET_NAMES), "horizons_h": list(F.HORIZONS_H), "multipolygon": "largest",
             "split_seed": split_seed, "split": split.ids(),
             "dataset": {"file": stem.with_suffix(".npz").name,
                         "sha256": file_sha256(stem.with_suffix(".npz"))}}
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    metrics_path = out_dir / "metrics.json"
    record = {}
    area_targets = tuple(i for i, n in enumerate(F.TARGET_NAMES) if "area" in n)
    for kind in kinds:
        cfg = TrainConfig(kind=kind, area_targets=area_targets, adaptive=adaptive_fused and kind == "ltc-fused",
                          **overrides)
        started = time.perf_counter()
        model, history = fit(train_t, val_t, cfg, horizons_h=F.HORIZONS_H, checkpoint=out_dir / f"{kind}.pt",
                             extra=extra, progress=progress)
        best = min(history, key=lambda h: h["val"]["loss"] - cfg.nll_weight * h["val"]["nll"])
        entry = {"train_config": asdict(cfg), "epochs_run": len(history), "best_epoch": best["epoch"],
                 "val_at_best": best["val"], "train_loss_at_best": best["train_loss"],
                 "train_seconds": round(time.perf_counter() - started, 1),
                 "n_params": sum(p.numel() for p in model.parameters()),
                 "train_windows": len(train_t), "val_windows": len(val_t),
                 "dataset": extra["dataset"], "split_seed": split_seed}
        # re-read just before writing: another `train --model` run may share the directory
        record = json.loads(metrics_path.read_text()) if metrics_path.exists() else {}
        record[kind] = entry
        metrics_path.write_text(json.dumps(record, indent=1) + "\n")
        if progress:
            print(f"{kind}: best epoch {best['epoch']} of {len(history)}, val MSE {best['val']['mse']:.4f}, "
                  f"{entry['train_seconds']} s -> {out_dir / (kind + '.pt')}")
    return record


def build_parser(parser: argparse.ArgumentParser | None = None) -> argparse.ArgumentParser:
    parser = parser or argparse.ArgumentParser(prog="oilspill-forecaster train")
    parser.description = "Train the LTC and LSTM forecasters on the committed OpenOil scenarios (CPU)."
    parser.add_argument("--model", action="append", choices=KINDS,
                        help="model to train (repeatable; default: all four)")
    parser.add_argument("--dataset", type=Path, help="dataset stem (default: the committed set)")
    parser.add_argument("--out", type=Path, default=WEIGHTS_DIR, help="weights directory (default: %(default)s)")
    parser.add_argument("--epochs", type=int, default=TrainConfig.epochs)
    parser.add_argument("--batch-size", type=int, default=TrainConfig.batch_size)
    parser.add_argument("--seed", type=int, default=TrainConfig.seed)
    parser.add_argument("--split-seed", type=int, default=0)
    parser.add_argument("--hidden", type=int, default=TrainConfig.hidden)
    parser.add_argument("--unfolds", type=int, default=TrainConfig.unfolds)
    parser.add_argument("--adaptive", action="store_true", help="adaptive step for the ltc-fused model")
    parser.add_argument("--threads", type=int, default=TrainConfig.threads)
    parser.add_argument("--max-minutes", type=float, help="wall-clock cap per model")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    return parser


def main(argv=None, args: argparse.Namespace | None = None) -> int:
    args = args or build_parser().parse_args(argv)
    kinds = args.model or list(KINDS)
    overrides = {"epochs": args.epochs, "batch_size": args.batch_size, "seed": args.seed, "hidden": args.hidden,
                 "unfolds": args.unfolds, "threads": args.threads,
                 "max_seconds": None if args.max_minutes is None else 60 * args.max_minutes}
    train_models(kinds, dataset_stem=args.dataset, out_dir=args.out, split_seed=args.split_seed,
                 progress=not args.quiet, adaptive_fused=args.adaptive, **overrides)
    return 0
