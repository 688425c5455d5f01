"""LTC and LSTM sequence models of the paper's "OilSpill model Architecture", as the learned correction
of the physics prior (``Corrector``: window features in, drift residual / area ratio / spread out).

Shared frame (both recurrent cores): input projection to 128 units with ReLU and LayerNorm,
the recurrent core over the 16-step window, multi-head attention from the last step over the
whole window, then a mean head and a softplus uncertainty head with one output row per horizon.

The LTC core follows Hasani et al. (2020): every unit obeys

    dx/dt = -(1/tau + f) * x + f * A,      f = sigmoid(W_in u + W_rec x + b) >= 0

so its effective time constant tau / (1 + tau f) depends on the input. The elapsed time between
two observations (per sample, in hours) is integrated by one of three solvers in ``unfolds``
equal sub-steps: classical RK4, explicit Euler, or the fused semi-implicit step

    x <- (x + h f A) / (1 + h (1/tau + f))

which is the paper's "LTC-Explicit"; with ``adaptive=True`` the fused sub-step shrinks to
h / (1 + rms(x)) (the paper's adaptive_dt, with the state norm per unit so that it does not
scale with the layer width) and more sub-steps are taken until the same elapsed time is covered.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn

from .kinds import LEARNED_KINDS as KINDS

SOLVERS = ("rk4", "euler", "fused")
HORIZONS_H = (3, 7, 11, 15)


class LTCCell(nn.Module):
    """One LTC layer; ``derivative`` is the ODE right-hand side, ``forward`` integrates it."""

    def __init__(self, input_size: int, hidden_size: int, solver: str = "rk4", unfolds: int = 6,
                 adaptive: bool = False, max_adaptive_steps: int = 64):
        super().__init__()
        if solver not in SOLVERS:
            raise ValueError(f"solver must be one of {SOLVERS}, not {solver!r}")
        if adaptive and solver != "fused":
            raise ValueError("the adaptive step belongs to the fused solver only")
        if unfolds < 1:
            raise ValueError(f"unfolds must be >= 1, not {unfolds}")
        self.solver, self.unfolds, self.adaptive = solver, unfolds, adaptive
        self.max_adaptive_steps = max_adaptive_steps
        self.input_map = nn.Linear(input_size, hidden_size)
        self.recurrent_map = nn.Linear(hidden_size, hidden_size, bias=False)
        # tau = softplus(raw) + tau_min, started near 1 h so hourly data is neither frozen nor stiff
        self.tau_raw = nn.Parameter(torch.full((hidden_size,), math.log(math.e - 1.0)))
        self.reversal = nn.Parameter(torch.empty(hidden_size).uniform_(-1.0, 1.0))
        self.tau_min = 1e-2
        nn.init.orthogonal_(self.recurrent_map.weight, gain=0.5)

    @property
    def tau(self) -> torch.Tensor:
        return nn.functional.softplus(self.tau_raw) + self.tau_min

    def gate(self, x: torch.Tensor, drive: torch.Tensor) -> torch.Tensor:
        """f(x, u) >= 0; ``drive`` = W_in u + b is computed once per observation."""
        return torch.sigmoid(drive + self.recurrent_map(x))

    def derivative(self, x: torch.Tensor, drive: torch.Tensor) -> torch.Tensor:
        f = self.gate(x, drive)
        return -(1.0 / self.tau + f) * x + f * self.reversal

    def fused_step(self, x: torch.Tensor, drive: torch.Tensor, h: torch.Tensor) -> torch.Tensor:
        f = self.gate(x, drive)
        return (x + h * f * self.reversal) / (1.0 + h * (1.0 / self.tau + f))

    def forward(self, u: torch.Tensor, x: torch.Tensor, dt: torch.Tensor) -> torch.Tensor:
        """Advance state ``x`` [B, H] by ``dt`` [B] hours under input ``u`` [B, F] held constant."""
        drive = self.input_map(u)
        if self.adaptive:
            return self._adaptive(x, drive, dt)
        h = (dt / self.unfolds).unsqueeze(-1)
        for _ in range(self.unfolds):
            if self.solver == "euler":
                x = x + h * self.derivative(x, drive)
            elif self.solver == "fused":
                x = self.fused_step(x, drive, h)
            else:
                k1 = self.derivative(x, drive)
                k2 = self.derivative(x + 0.5 * h * k1, drive)
                k3 = self.derivative(x + 0.5 * h * k2, drive)
                k4 = self.derivative(x + h * k3, drive)
                x = x + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        return x

    def _adaptive(self, x: torch.Tensor, drive: torch.Tensor, dt: torch.Tensor) -> torch.Tensor:
        """Fused steps of h/(1+rms(x)) until each sample has covered its own dt.

        The fused step is stable for any h, so when the step budget runs out the last step
        simply takes all the remaining time."""
        base = (dt / self.unfolds).unsqueeze(-1)
        remaining = dt.unsqueeze(-1).clone()
        for step in range(self.max_adaptive_steps):
            if not bool((remaining > 1e-9).any()):
                break
            rms = x.detach().pow(2).mean(dim=-1, keepdim=True).sqrt()
            h = torch.minimum(base / (1.0 + rms), remaining)
            if step == self.max_adaptive_steps - 1:
                h = remaining
            x = self.fused_step(x, drive, h)
            remaining = remaining - h
        return x


class LTCLayer(nn.Module):
    """Runs an LTCCell over a window with per-step elapsed times."""

    def __init__(self, input_size: int, hidden_size: int, **cell_args):
        super().__init__()
        self.hidden_size = hidden_size
        self.cell = LTCCell(input_size, hidden_size, **cell_args)

    def forward(self, seq: torch.Tensor, dt: torch.Tensor) -> torch.Tensor:
        x = seq.new_zeros(seq.shape[0], self.hidden_size)
        states = []
        for t in range(seq.shape[1]):
            x = self.cell(seq[:, t], x, dt[:, t])
            states.append(x)
        return torch.stack(states, dim=1)


class LSTMCore(nn.Module):
    """The paper's baseline: LSTM 128 then LSTM 64, dropout 0.1 between; ignores dt."""

    def __init__(self, input_size: int, sizes: tuple[int, int] = (128, 64), dropout: float = 0.1):
        super().__init__()
        self.first = nn.LSTM(input_size, sizes[0], batch_first=True)
        self.dropout = nn.Dropout(dropout)
        self.second = nn.LSTM(sizes[0], sizes[1], batch_first=True)
        self.hidden_size = sizes[1]

    def forward(self, seq: torch.Tensor, dt: torch.Tensor) -> torch.Tensor:
        out, _ = self.first(seq)
        out, _ = self.second(self.dropout(out))
        return out


@dataclass(frozen=True)
class ModelConfig:
    """Everything needed to rebuild a model from a checkpoint."""

    kind: str = "ltc-rk4"
    n_features: int = 25
    n_targets: int = 3
    horizons_h: tuple[int, ...] = HORIZONS_H
    hidden: int = 64
    heads: int = 4
    unfolds: int = 4
    adaptive: bool = False

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"model kind must be one of {KINDS}, not {self.kind!r}")

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> "ModelConfig":
        data = dict(data)
        data["horizons_h"] = tuple(data.get("horizons_h", HORIZONS_H))
        return cls(**data)


class SpillForecaster(nn.Module):
    """Window of features -> (mean, sigma), each [B, n_horizons, n_targets]."""

    def __init__(self, config: ModelConfig):
        super().__init__()
        self.config = config
        self.project = nn.Sequential(nn.Linear(config.n_features, config.hidden), nn.ReLU(),
                                     nn.LayerNorm(config.hidden))
        if config.kind == "lstm":
            self.core = LSTMCore(config.hidden)
        else:
            self.core = LTCLayer(config.hidden, config.hidden, solver=config.kind.split("-")[1],
                                 unfolds=config.unfolds, adaptive=config.adaptive)
        width = self.core.hidden_size
        self.attention = nn.MultiheadAttention(width, config.heads, batch_first=True)
        self.norm = nn.LayerNorm(width)
        out = len(config.horizons_h) * config.n_targets
        self.mean_head = nn.Linear(width, out)
        self.sigma_head = nn.Linear(width, out)

    def forward(self, x: torch.Tensor, dt: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``x`` [B, T, F] scaled features, ``dt`` [B, T] hours since the previous observation."""
        if x.ndim != 3 or x.shape[-1] != self.config.n_features:
            raise ValueError(f"expected input [batch, steps, {self.config.n_features}], got {tuple(x.shape)}")
        if dt.shape != x.shape[:2]:
            raise ValueError(f"dt must be [batch, steps] = {tuple(x.shape[:2])}, got {tuple(dt.shape)}")
        if not (torch.isfinite(x).all() and torch.isfinite(dt).all()):
            raise ValueError("input window holds NaN or infinite values")
        states = self.core(self.project(x), dt)
        last = states[:, -1:]
        context, _ = self.attention(last, states, states, need_weights=False)
        summary = self.norm(last + context).squeeze(1)
        shape = (x.shape[0], len(self.config.horizons_h), self.config.n_targets)
        mean = self.mean_head(summary).view(shape)
        sigma = nn.functional.softplus(self.sigma_head(summary)).view(shape) + 1e-4
        return mean, sigma


def build_model(kind: str = "ltc-rk4", **kwargs) -> SpillForecaster:
    return SpillForecaster(ModelConfig(kind=kind, **kwargs))



class Corrector:
    """A trained model with its scalers: ``Observations`` -> ``engine.Correction`` of the physics prior."""

    def __init__(self, model: SpillForecaster, extra: dict):
        from .features import FeatureScaler

        self.model = model
        self.feature_scaler = FeatureScaler.from_dict(extra["feature_scaler"])
        self.target_mean = np.asarray(extra["target_scaler"]["mean"], float)
        self.target_std = np.asarray(extra["target_scaler"]["std"], float)
        self.horizons_h = tuple(extra["horizons_h"])
        self.trained_split = extra.get("split", {})   # the scenario ids it was trained and stopped on

    @classmethod
    def load(cls, path) -> "Corrector":
        model, blob = load_checkpoint(path)
        return cls(model, blob["extra"])

    @torch.inference_mode()
    def predict(self, x: np.ndarray, dt: np.ndarray, batch: int = 512) -> tuple[np.ndarray, np.ndarray]:
        """Raw-unit (mean, sigma) [N, H, 3] for windows x [N, W, F] (unscaled), dt [N, W]."""
        means, sigmas = [], []
        for start in range(0, len(x), batch):
            xb = torch.as_tensor(self.feature_scaler.transform(x[start:start + batch]), dtype=torch.float32)
            db = torch.as_tensor(dt[start:start + batch], dtype=torch.float32)
            mean, sigma = self.model(xb, db)
            means.append(mean.numpy() * self.target_std + self.target_mean)
            sigmas.append(sigma.numpy() * self.target_std)
        mean, sigma = np.concatenate(means), np.concatenate(sigmas)
        if not (np.isfinite(mean).all() and np.isfinite(sigma).all()):
            raise ValueError(f"{self.model.config.kind} diverged on this window (its steps are integrated in a fixed "
                             "number of sub-steps); the fused solver stays bounded for any step: use --model ltc-fused")
        return mean, sigma

    def corrections(self, observations, params) -> list:
        """One ``engine.Correction`` per ``Observations`` (one batched model call): what the model adds
        to the prior's own correction from the observed history (``engine.history_correction``, added
        by ``engine.forecast_plane``)."""
        from .engine import correction_from, window_inputs

        inputs = [window_inputs(obs, params) for obs in observations]
        mean, sigma = self.predict(np.array([i[0] for i in inputs]), np.array([i[1] for i in inputs]))
        return [correction_from(m, s, i[2]) for m, s, i in zip(mean, sigma, inputs)]

    def correction(self, obs, params):
        return self.corrections([obs], params)[0]


def load_checkpoint(path) -> tuple[SpillForecaster, dict]:
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such checkpoint (run `python -m oilspill_moos.forecaster train`)")
    blob = torch.load(path, map_location="cpu", weights_only=False)
    model = SpillForecaster(ModelConfig.from_dict(blob["model_config"]))
    model.load_state_dict(blob["state_dict"])
    model.eval()
    return model, blob
