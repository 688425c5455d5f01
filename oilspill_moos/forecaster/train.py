"""Training the learned correction of the physics prior, and calibrating every kind's uncertainty.

Examples: ``windows.scenario_cases`` of the training scenarios (several observation-noise draws each).
For a case ending at observation time t and horizon h the targets are, in the frame of
``features.window_features`` (x along the forcing-predicted drift):

- the drift residual: true centroid at t + h minus the prior's centroid (the mean of its particles),
  in km;
- the log area ratio: log(true area / prior footprint area).

Loss: MSE on the scaled targets, plus a Gaussian negative log-likelihood for the spread head on the
*detached* mean (so the spread never changes what the mean learns). AdamW, early stopping on the
validation MSE, one CPU thread per model; ``--max-minutes`` caps each model's wall time.

Gains (``fit_gains``): on the validation cases, per horizon and outline class (lobed or not), how much
of a learned kind's residual drift to keep (``engine.Settings.gain``), the share with the highest mean IoU.

Calibration (``calibrate``): on the validation cases every kind forecasts, and per horizon its ensemble
spread is scaled so that the nominal 95 % radius (``engine.RADIUS_95`` x ``uncertainty_m``) holds the
true centroid in 95 % of them, in each forcing family (steady, varying) of the validation split. The
gains and factors go to ``calibration.json`` beside the weights, with the prior's parameters and the training
record.
"""
from __future__ import annotations

import argparse
import copy
import hashlib
import json
import math
import multiprocessing
import os
import pickle
import random
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from shapely import affinity
from torch import nn
from tqdm import tqdm

from . import engine as E
from . import features as F
from .models import KINDS, ModelConfig, SpillForecaster
from .physics import DriftParameters, ParticleFootprint, drift
from .windows import scenario_cases

WEIGHTS_DIR = Path(__file__).resolve().parent / "weights"
CALIBRATION_FILE = "calibration.json"
# kind -> (learning rate, early-stopping patience in epochs, sub-steps per observation); the LTC rates
# are the paper's. RK4 takes 2 sub-steps (8 evaluations of the ODE per observation against Euler's 4),
# which keeps one forecast within 50 ms on one core (benchmarks/forecaster_bench.py).
SOLVER_DEFAULTS = {"ltc-rk4": (3e-3, 6, 2), "ltc-fused": (3e-3, 6, 4), "ltc-euler": (3e-3, 6, 4), "lstm": (3e-3, 6, 4)}


@dataclass
class TrainConfig:
    kind: str = "ltc-rk4"
    epochs: int = 30
    batch_size: int = 64
    lr: float | None = None            # None: SOLVER_DEFAULTS
    nll_weight: float = 0.1
    weight_decay: float = 1e-3
    patience: int | None = None        # None: SOLVER_DEFAULTS
    seed: int = 0
    hidden: int = 64
    unfolds: int | None = None         # None: SOLVER_DEFAULTS
    adaptive: bool = False
    grad_clip: float = 1.0
    threads: int = 1
    max_seconds: float | None = None   # wall-clock cap; training stops after the epoch that passes it

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"--model must be one of {KINDS}, not {self.kind!r}")
        lr, patience, unfolds = SOLVER_DEFAULTS[self.kind]
        self.lr = lr if self.lr is None else self.lr
        self.patience = patience if self.patience is None else self.patience
        self.unfolds = unfolds if self.unfolds is None else self.unfolds


@dataclass
class WindowTensors:
    """Model-ready windows: x [N, T, F] scaled, dt [N, T] hours, y [N, H, K] scaled targets."""

    x: torch.Tensor
    dt: torch.Tensor
    y: torch.Tensor

    def __post_init__(self):
        self.x, self.dt, self.y = (torch.as_tensor(np.asarray(a), dtype=torch.float32) for a in (self.x, self.dt, self.y))
        if not (len(self.x) == len(self.dt) == len(self.y)):
            raise ValueError(f"window arrays disagree in length: {len(self.x)}, {len(self.dt)}, {len(self.y)}")
        if len(self.x) == 0:
            raise ValueError("no windows to train or evaluate on")

    def __len__(self) -> int:
        return len(self.x)


def seed_everything(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)


def forecast_loss(mean, sigma, target, *, nll_weight: float) -> tuple[torch.Tensor, dict[str, float]]:
    mse = nn.functional.mse_loss(mean, target)
    nll = nn.functional.gaussian_nll_loss(mean.detach(), target, sigma.pow(2))
    total = mse + nll_weight * nll
    return total, {"loss": total.item(), "mse": mse.item(), "nll": nll.item()}


# ---------------------------------------------------------------------------------------------------
# Examples

@dataclass
class Examples:
    x: np.ndarray          # [N, W, F] unscaled features
    dt: np.ndarray         # [N, W] hours
    y: np.ndarray          # [N, H, 3] raw targets
    scenario: list[str]


def case_example(case, params: DriftParameters, horizons_h=F.HORIZONS_H):
    """(x, dt, y) of one case; y [H, 3] = frame residual km (2) of the corrected prior (the prior moved
    on by its history correction, ``engine.history_correction``), log area ratio."""
    x, dt, angle = E.window_inputs(case.obs, params)
    base = E.history_correction(case.obs, params, horizons_h).drift_m
    horizons_s = 3600.0 * np.asarray(horizons_h, float)
    moved, start = drift(case.obs.geometries[-1], 0.0, horizons_s, case.obs.track, params, diffuse=False)
    method = ParticleFootprint(case.obs.geometries[-1], start)
    back = F.rotation(-angle)
    y = np.zeros((len(horizons_h), 3))
    for j, (p, truth) in enumerate(zip(moved, case.truth_shapes)):
        y[j, :2] = back @ (truth.centroid - p.mean(axis=0) - base[j]) / 1e3
        y[j, 2] = math.log(truth.area / max(method.area(p), 1.0))
    return x, dt, y


def exact_draw(draw: int) -> bool:
    """Every third noise draw of a training scenario is given the exact forcing, the others the erroneous
    one: the model sees both, and learns to trust the forcing where the history agrees with it."""
    return draw % 3 == 2


def held_draw(draw: int) -> bool:
    """Every other noise draw is given no forcing over the horizon (the latest held, as the public API
    does without ``horizon_forcing``): the model learns both cases, told apart by ``forcing_ahead``."""
    return draw % 2 == 1


# Raised whenever what an example holds changes in a way the cache key below cannot see (2: targets
# against the prior without its random walk, observations repaired by make_valid's "structure" method;
# 3: the forcing error and constant-velocity weight of a lobed outline read from one lobe's track).
EXAMPLES_VERSION = 3


def scenario_examples(scenario, draw: int, params: DriftParameters, cache_dir: Path | None = None) -> list:
    """[(x, dt, y)] of one scenario and noise draw; read from / written to ``cache_dir`` (one pickle per
    scenario and draw, reused only when built from the same scenario, draw, prior and features)."""
    key = {"version": EXAMPLES_VERSION, "scenario_id": scenario.scenario_id, "seed": scenario.seed, "observations": len(scenario), "draw": draw,
           "exact": exact_draw(draw), "held": held_draw(draw), "drift": params.to_dict(), "features": list(F.FEATURE_NAMES),
           "targets": list(F.TARGET_NAMES), "drift_memory": [E.DRIFT_MEMORY_H, E.CENTROID_NOISE_M, E.DRIFT_PRIOR_MS[True], E.DRIFT_PRIOR_MS[False]]}
    path = None if cache_dir is None else Path(cache_dir) / f"{scenario.scenario_id}-{draw}.pkl"
    if path is not None and path.is_file():
        blob = pickle.loads(path.read_bytes())
        if blob.get("key") == key:
            return blob["examples"]
    examples = [case_example(case, params) for case in scenario_cases(scenario, noise_seed=draw, exact=exact_draw(draw),
                                                                         held=held_draw(draw))]
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        partial = path.with_suffix(f".{os.getpid()}.part")
        partial.write_bytes(pickle.dumps({"key": key, "examples": examples}))
        partial.replace(path)       # atomic: a concurrent reader sees the old file or the whole new one
    return examples


def worker_pool(workers: int) -> ProcessPoolExecutor:
    """Processes for the parallel parts of training ("spawn": torch's thread pools do not survive fork)."""
    return ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"))


def mapped(function, jobs: list, workers: int):
    """``map(function, jobs)`` in order, over ``workers`` processes when more than one."""
    if workers <= 1 or len(jobs) <= 1:
        yield from map(function, jobs)
        return
    with worker_pool(min(workers, len(jobs))) as pool:
        yield from pool.map(function, jobs)


def _scenario_job(job) -> list:
    return scenario_examples(*job)


def build_examples(scenarios, params: DriftParameters, noise_draws: int = 1, progress: bool = True,
                   cache_dir: Path | None = None, workers: int = 1) -> Examples:
    xs, dts, ys, ids = [], [], [], []
    jobs = [(s, d, params, cache_dir) for s in scenarios for d in range(noise_draws)]
    results = mapped(_scenario_job, jobs, workers)
    for (s, *_), examples in tqdm(zip(jobs, results), total=len(jobs), desc="examples", disable=not progress,
                                  leave=False):
        for x, dt, y in examples:
            xs.append(x), dts.append(dt), ys.append(y), ids.append(s.scenario_id)
    return Examples(np.array(xs), np.array(dts), np.array(ys), ids)


# ---------------------------------------------------------------------------------------------------
# Fitting one model

def fit(train: WindowTensors, val: WindowTensors, cfg: TrainConfig, horizons_h=F.HORIZONS_H,
        checkpoint: Path | None = None, extra: dict | None = None, progress: bool = True, position: int = 0):
    """Train one model; returns (best model, history). Best = lowest validation MSE."""
    threads = torch.get_num_threads()
    torch.set_num_threads(cfg.threads)
    try:
        return _fit(train, val, cfg, horizons_h, checkpoint, extra, progress, position)
    finally:
        torch.set_num_threads(threads)


@torch.no_grad()
def evaluate_loss(model: SpillForecaster, data: WindowTensors, cfg: TrainConfig, batch: int = 512) -> dict:
    model.eval()
    sums: dict[str, float] = {}
    for start in range(0, len(data), batch):
        sl = slice(start, start + batch)
        mean, sigma = model(data.x[sl], data.dt[sl])
        _, parts = forecast_loss(mean, sigma, data.y[sl], nll_weight=cfg.nll_weight)
        for key, value in parts.items():
            sums[key] = sums.get(key, 0.0) + value * len(data.x[sl])
    return {key: value / len(data) for key, value in sums.items()}


def _fit(train, val, cfg, horizons_h, checkpoint, extra, progress, position):
    seed_everything(cfg.seed)
    model = SpillForecaster(ModelConfig(kind=cfg.kind, n_features=train.x.shape[-1], n_targets=train.y.shape[-1],
                                        horizons_h=tuple(horizons_h), hidden=cfg.hidden, unfolds=cfg.unfolds,
                                        adaptive=cfg.adaptive))
    optimiser = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    generator = torch.Generator().manual_seed(cfg.seed)
    best_state, best_score, best_epoch, history = None, float("inf"), -1, []
    started = time.perf_counter()
    bar = tqdm(range(cfg.epochs), desc=cfg.kind, disable=not progress, position=position)
    for epoch in bar:
        model.train()
        order = torch.randperm(len(train), generator=generator)
        running = 0.0
        for start in range(0, len(train), cfg.batch_size):
            idx = order[start:start + cfg.batch_size]
            mean, sigma = model(train.x[idx], train.dt[idx])
            loss, parts = forecast_loss(mean, sigma, train.y[idx], nll_weight=cfg.nll_weight)
            optimiser.zero_grad()
            loss.backward()
            nn.utils.clip_grad_norm_(model.parameters(), cfg.grad_clip)
            optimiser.step()
            running += parts["loss"] * len(idx)
        val_parts = evaluate_loss(model, val, cfg)
        history.append({"epoch": epoch, "train_loss": running / len(train), "val": val_parts,
                        "seconds": round(time.perf_counter() - started, 1)})
        bar.set_postfix(train=f"{running / len(train):.4f}", val_mse=f"{val_parts['mse']:.4f}")
        if val_parts["mse"] < best_score:
            best_score, best_epoch, best_state = val_parts["mse"], epoch, copy.deepcopy(model.state_dict())
            if checkpoint is not None:
                save_checkpoint(checkpoint, model, cfg, history, extra)
        if epoch - best_epoch >= cfg.patience:
            break
        if cfg.max_seconds is not None and time.perf_counter() - started > cfg.max_seconds:
            break
    model.load_state_dict(best_state)
    model.eval()
    return model, history


def _train_job(job) -> dict:
    """Fit one kind (in its own process when training in parallel); its line of the training record."""
    train_t, val_t, cfg, checkpoint, extra, progress, position = job
    started = time.perf_counter()
    model, history = fit(train_t, val_t, cfg, checkpoint=checkpoint, extra=extra, progress=progress,
                         position=position)
    best = min(history, key=lambda h: h["val"]["mse"])
    return {"train_config": asdict(cfg), "epochs_run": len(history), "best_epoch": best["epoch"],
            "val_at_best": best["val"], "train_loss_at_best": best["train_loss"],
            "train_seconds": round(time.perf_counter() - started, 1),
            "n_params": sum(p.numel() for p in model.parameters()),
            "train_windows": len(train_t), "val_windows": len(val_t)}


def save_checkpoint(path: Path, model: SpillForecaster, cfg: TrainConfig, history: list, extra: dict | None):
    """Weights, both configs, the history and caller extras (scalers, data provenance) in one .pt."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    torch.save({"model_config": model.config.to_dict(), "train_config": asdict(cfg),
                "state_dict": {k: v.detach().clone() for k, v in model.state_dict().items()},
                "history": history, "extra": extra or {}}, path)


# ---------------------------------------------------------------------------------------------------
# Calibration

def calibrate(cases, kinds, settings: E.Settings, correctors: dict, horizons_h=F.HORIZONS_H, groups=None) -> dict:
    """kind -> [H] spread factors so that RADIUS_95 x uncertainty_m holds 95 % of ``cases``' true centroids;
    with ``groups`` (a label per case), 95 % of each group's: the largest of the groups' factors
    (group-wise conformal), so a forecast is covered whichever kind of case it is."""
    labels = np.asarray(groups if groups is not None else [""] * len(cases))
    unscaled = E.Settings(settings.params, {}, settings.members, settings.residual_gain)
    factors = {}
    for kind in kinds:
        ratios = []
        corrections = (correctors[kind].corrections([c.obs for c in cases], settings.params) if kind in correctors
                       else [None] * len(cases))
        for case, correction in zip(cases, corrections):
            out = E.forecast_plane(kind, case.obs, horizons_h, unscaled, correction, contours=False)
            ratios.append([np.linalg.norm(f.centroid - t.centroid) / max(f.raw_spread_m, 1e-6)
                           for f, t in zip(out, case.truth_shapes)])
        factors[kind] = groupwise_factors(np.array(ratios), labels)
    return factors


# Gain factors tried per horizon (``fit_gains``): 0 keeps the prior alone, 3 the whole residual
# wherever the history is not nearly a straight line (cv_weight under 2/3). Fitted on every
# GAIN_STRIDE-th validation case (the IoU of every candidate is most of a calibration's time).
GAIN_FACTORS = (0.0, 0.5, 1.0, 1.5, 2.0, 3.0)
GAIN_STRIDE = 3
MIN_GAIN_CASES = 20      # fewest cases of an outline class fitted on its own (``fit_gains``)


def fit_gains(cases, corrector, params: DriftParameters, horizons_h=F.HORIZONS_H) -> dict[bool, list[float]]:
    """{lobed: [H] factors of ``engine.Settings.gain``} for one learned kind: per horizon and outline
    class (``engine.lobed`` or not) the one of ``GAIN_FACTORS`` whose forecasts have the highest mean
    IoU on ``cases`` (validation cases); a class with fewer than ``MIN_GAIN_CASES`` cases takes the
    factors of all of them. Why by class: the learned drift of a lobed outline reads a centroid that
    jumps as lobes split and trade area, and the training set's lobes are separate releases (founding
    OpenOil set, multi-lobe slicks at 15 h: 0.27 with the shared factors, the prior alone 0.45). The
    residual moves the corrected prior's footprint rigidly, so each candidate is the prior's footprint
    translated by its share of the residual drift."""
    from .evaluate import iou, valid

    plain = E.Settings(params)
    scores, classes = [], []
    for case, correction in zip(cases, corrector.corrections([c.obs for c in cases], params)):
        prior = [valid(f.geometry) for f in E.forecast_plane("physics-corrected", case.obs, horizons_h, plain, contours=False)]
        truth = [valid(t) for t in case.truth]
        residual = correction.at(tuple(horizons_h)).drift_m
        weight = E.constant_velocity_weight(case.obs, params)
        shares = np.clip(np.asarray(GAIN_FACTORS) * (1.0 - weight), 0.0, 1.0)
        scores.append([[iou(affinity.translate(g, *(share * r)), t) for g, r, t in zip(prior, residual, truth)]
                       for share in shares])
        classes.append(E.lobed(case.obs.shapes[-1]))
    scores, classes = np.asarray(scores), np.asarray(classes, bool)          # [N, factors, H], [N]

    def best(rows: np.ndarray) -> list[float]:
        return [GAIN_FACTORS[i] for i in rows.mean(axis=0).argmax(axis=0)]

    return {lobed: best(scores[classes == lobed]) if (classes == lobed).sum() >= MIN_GAIN_CASES else best(scores)
            for lobed in (False, True)}


def groupwise_factors(ratios: np.ndarray, labels: np.ndarray, level: float = 0.95) -> list[float]:
    """[H] factors from normalised errors [N, H] (error / raw spread): per horizon the largest over the
    label groups of the split-conformal quantile, over ``RADIUS_95``, so that each group's cases fall
    within RADIUS_95 x factor x spread at ``level`` or more."""
    return [max(conformal_quantile(r[labels == g], level) / E.RADIUS_95 for g in np.unique(labels)) for r in ratios.T]


def conformal_quantile(scores: np.ndarray, level: float) -> float:
    """The split-conformal quantile: the ceil((n + 1) level)-th smallest of n scores, so that a new
    exchangeable case falls below it with probability at least ``level``."""
    ordered = np.sort(np.asarray(scores, float))
    k = min(math.ceil((len(ordered) + 1) * level), len(ordered))
    return float(ordered[k - 1])


def read_calibration(weights_dir: Path) -> dict:
    path = Path(weights_dir) / CALIBRATION_FILE
    return json.loads(path.read_text()) if path.is_file() else {}


# ---------------------------------------------------------------------------------------------------
# The `train` command

def file_sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def train_models(kinds, *, dataset_stem=None, out_dir: Path = WEIGHTS_DIR, split_seed: int = 0, noise_draws: int = 4,
                 progress: bool = True, adaptive_fused: bool = False, examples_cache: Path | None = None,
                 calibrate: bool = True, workers: int = 1, **overrides) -> dict:
    """Train each kind on the same examples and scalers; write ``<kind>.pt``, then calibrate every kind
    (learned and baselines) on the validation split into ``calibration.json`` (with the training record).
    Examples, kinds and calibrations are spread over ``workers`` processes (each model on one thread, so
    the weights do not depend on ``workers``)."""
    from . import dataset as D

    stem = Path(dataset_stem) if dataset_stem is not None else D.GULF_STEM
    scenarios = D.load_dataset(stem)
    split = D.split_scenarios(scenarios, seed=split_seed)
    params = DriftParameters()
    started = time.perf_counter()
    train_ex = build_examples(split.train, params, noise_draws, progress, examples_cache, workers)
    val_ex = build_examples(split.val, params, 2, progress, examples_cache, workers)     # with and without forcing ahead
    feature_scaler = F.FeatureScaler.fit(train_ex.x.reshape(-1, train_ex.x.shape[-1]))
    mean, std = train_ex.y.mean(axis=0), np.maximum(train_ex.y.std(axis=0), 1e-6)
    extra = {"feature_scaler": feature_scaler.to_dict(), "target_scaler": {"mean": mean.tolist(), "std": std.tolist()},
             "target_names": list(F.TARGET_NAMES), "horizons_h": list(F.HORIZONS_H), "drift": params.to_dict(),
             "split_seed": split_seed, "split": split.ids(),
             "dataset": {"file": stem.with_suffix(".npz").name, "sha256": file_sha256(stem.with_suffix(".npz"))}}

    def tensors(ex):
        return WindowTensors(feature_scaler.transform(ex.x), ex.dt, (ex.y - mean) / std)

    train_t, val_t = tensors(train_ex), tensors(val_ex)
    prep_seconds = round(time.perf_counter() - started, 1)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    jobs = [(train_t, val_t, TrainConfig(kind=kind, adaptive=adaptive_fused and kind == "ltc-fused", **overrides),
             out_dir / f"{kind}.pt", extra, progress, n % max(workers, 1)) for n, kind in enumerate(kinds)]
    record = {}
    for kind, result in zip(kinds, mapped(_train_job, jobs, workers)):
        record[kind] = {**result, "noise_draws": noise_draws, "example_seconds": prep_seconds,
                        "dataset": extra["dataset"], "split_seed": split_seed, "workers": workers}
        if progress:
            print(f"{kind}: best epoch {result['best_epoch']} of {result['epochs_run']}, val MSE "
                  f"{result['val_at_best']['mse']:.4f}, {result['train_seconds']} s -> {out_dir / (kind + '.pt')}",
                  flush=True)
    if calibrate:
        write_calibration(out_dir, split, params, record, progress, workers)
    else:
        merge_training_record(out_dir, record)
    return record


def merge_training_record(out_dir: Path, record: dict) -> None:
    """Add ``record`` to ``calibration.json``'s training record without recalibrating."""
    blob = read_calibration(out_dir)
    blob["training"] = {**blob.get("training", {}), **record}
    (Path(out_dir) / CALIBRATION_FILE).write_text(json.dumps(blob, indent=1) + "\n")


def _calibration_job(job) -> tuple[list, dict, int]:
    """(spread factors per horizon, {``Settings.gain_key``: gain factors per horizon}, empty for a
    baseline, cases) of one kind on the validation cases with forcing ahead or held. A learned kind's
    gains are fitted first
    (``fit_gains``, on the cases given the erroneous forcing and the exact one: a user may have either,
    and a residual that pays with erroneous forcing can cost with exact), then its spread calibrated
    with them on the erroneous-forcing cases, per forcing family (``forcing_family``):
    the validation split mixes steady and varying forcing, and a factor pooled over both under-covers
    the harder varying cases."""
    from .models import Corrector

    out_dir, kind, held, scenarios, params = job
    torch.set_num_threads(1)
    correctors = {kind: Corrector.load(out_dir / f"{kind}.pt")} if kind in KINDS else {}
    cases, groups = validation_cases(held, scenarios)
    gains = {}
    if correctors:
        exact, _ = validation_cases(held, scenarios, exact=True, stride=GAIN_STRIDE)
        gains = {E.Settings.gain_key(kind, not held, lobed): factors
                 for lobed, factors in fit_gains(cases[::GAIN_STRIDE] + exact, correctors[kind], params).items()}
    settings = E.Settings(params, residual_gain=gains)
    return calibrate(cases, [kind], settings, correctors, groups=groups)[kind], gains, len(cases)


_VALIDATION_CASES: dict = {}


def validation_cases(held: bool, scenarios, exact: bool = False, stride: int = 1) -> tuple[list, list[str]]:
    """(cases, forcing family of each) of the validation scenarios at every ``stride``-th observation,
    given the erroneous forcing or ``exact``, built once per process and mode for all the kinds
    calibrated there."""
    key = (held, exact, stride, tuple(s.scenario_id for s in scenarios))
    if key not in _VALIDATION_CASES:
        cases, groups = [], []
        for scenario in scenarios:
            made = scenario_cases(scenario, stride=stride, held=held, exact=exact)
            cases += made
            groups += [forcing_family(scenario)] * len(made)
        _VALIDATION_CASES[key] = cases, groups
    return _VALIDATION_CASES[key]


def forcing_family(scenario) -> str:
    """"steady" for a scenario of steady wind and current (``simulate.STEADY_REGIMES``), else "varying"
    (veering or shifting wind, inertial and tidal current): the calibration groups."""
    from .simulate import STEADY_REGIMES

    return "steady" if scenario.regime in STEADY_REGIMES else "varying"


def write_calibration(out_dir: Path, split, params: DriftParameters, record: dict, progress: bool = True,
                      workers: int = 1) -> dict:
    """Calibrate every kind with weights in ``out_dir`` and every baseline on every observation of the
    validation split (never trained on: on training cases the learned kinds' errors are optimistically
    small).

    The recorded split's ``test`` lists every scenario never used for training or calibration: the
    Gulf set's out-of-distribution split and the whole DWH-site set (the demos replay those)."""
    from .dataset import load_dataset

    learned = [k for k in KINDS if (Path(out_dir) / f"{k}.pt").is_file()]
    jobs = [(Path(out_dir), kind, held, split.val, params) for held in (False, True)
            for kind in [*learned, *E.BASELINE_KINDS]]
    factors, gains = {}, {}
    for (_, kind, held, *_), (value, gain, cases) in tqdm(zip(jobs, mapped(_calibration_job, jobs, workers)),
                                                         total=len(jobs), desc="calibration", disable=not progress):
        factors[E.Settings.scale_key(kind, forcing_ahead=not held)] = value
        gains.update(gain)
    ids = split.ids()
    ids["test"] = ids["test"] + [s.scenario_id for s in load_dataset()]
    # re-read just before writing: another `train --model` run may share the directory
    record = {**read_calibration(out_dir).get("training", {}), **record}
    blob = {"drift": params.to_dict(), "spread_scale": factors, "residual_gain": gains,
            "calibration_cases": cases,
            "members": E.Settings(params).members, "split": ids, "training": record}
    (Path(out_dir) / CALIBRATION_FILE).write_text(json.dumps(blob, indent=1) + "\n")
    return blob


def build_parser(parser: argparse.ArgumentParser | None = None) -> argparse.ArgumentParser:
    parser = parser or argparse.ArgumentParser(prog="oilspill-forecaster train")
    parser.description = ("Train the learned corrections (LTC RK4/Euler/fused, LSTM) of the physics prior on the "
                          "committed Gulf scenarios, then calibrate every kind's uncertainty (CPU).")
    parser.add_argument("--model", action="append", choices=KINDS, help="model to train (repeatable; default: all four)")
    parser.add_argument("--dataset", type=Path, help="dataset stem (default: the committed Gulf set)")
    parser.add_argument("--out", type=Path, default=WEIGHTS_DIR, help="weights directory (default: %(default)s)")
    parser.add_argument("--epochs", type=int, default=TrainConfig.epochs)
    parser.add_argument("--batch-size", type=int, default=TrainConfig.batch_size)
    parser.add_argument("--seed", type=int, default=TrainConfig.seed)
    parser.add_argument("--split-seed", type=int, default=0)
    parser.add_argument("--noise-draws", type=int, default=4, help="observation-noise draws per training scenario "
                        "(every third given the exact forcing, every other none over the horizon)")
    parser.add_argument("--hidden", type=int, default=TrainConfig.hidden)
    parser.add_argument("--unfolds", type=int, help="LTC sub-steps per observation (default: per solver, 2 for RK4, 4 otherwise)")
    parser.add_argument("--adaptive", action="store_true", help="adaptive step for the ltc-fused model")
    parser.add_argument("--threads", type=int, default=TrainConfig.threads, help="torch threads per model")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                        help="processes for examples, models and calibration (default: one per core, %(default)s)")
    parser.add_argument("--max-minutes", type=float, help="wall-clock cap per model")
    parser.add_argument("--examples-cache", type=Path, help="directory of built examples, one file per scenario and "
                        "noise draw: reused when built from the same scenario, prior and features, written otherwise "
                        "(building takes minutes)")
    parser.add_argument("--no-calibration", action="store_true",
                        help="train only (add to the training record); calibrate later with --calibrate-only, e.g. "
                        "after training the kinds in two processes")
    parser.add_argument("--calibrate-only", action="store_true",
                        help="train nothing: recalibrate the kinds whose weights are in --out")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    return parser


def main(argv=None, args: argparse.Namespace | None = None) -> int:
    args = args or build_parser().parse_args(argv)
    if args.calibrate_only:
        from . import dataset as D

        split = D.split_scenarios(D.load_dataset(args.dataset or D.GULF_STEM), seed=args.split_seed)
        write_calibration(Path(args.out), split, DriftParameters(), {}, progress=not args.quiet, workers=args.workers)
        return 0
    kinds = args.model or list(KINDS)
    overrides = {"epochs": args.epochs, "batch_size": args.batch_size, "seed": args.seed, "hidden": args.hidden,
                 "unfolds": args.unfolds, "threads": args.threads,
                 "max_seconds": None if args.max_minutes is None else 60 * args.max_minutes}
    train_models(kinds, dataset_stem=args.dataset, out_dir=args.out, split_seed=args.split_seed,
                 noise_draws=args.noise_draws, progress=not args.quiet, adaptive_fused=args.adaptive,
                 examples_cache=args.examples_cache, calibrate=not args.no_calibration, workers=args.workers,
                 **overrides)
    return 0
