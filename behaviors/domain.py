"""The IvP decision domain: named variables on uniform grids (`domain = name:low:high:npts`)."""
from __future__ import annotations

import functools

import numpy as np
from pydantic import BaseModel, model_validator


class DomainVar(BaseModel):
    name: str
    low: float
    high: float
    npts: int
    optional: bool = False

    @model_validator(mode="after")
    def _check(self) -> "DomainVar":
        if self.high < self.low or self.npts < 1 or (self.low == self.high and self.npts != 1):
            raise ValueError(f"bad domain {self.name}:{self.low}:{self.high}:{self.npts}")
        return self

    @property
    def delta(self) -> float:
        return (self.high - self.low) / (self.npts - 1) if self.npts > 1 else 0.0

    @property
    def values(self) -> np.ndarray:
        """The grid points, built once per grid (every ZAIC and the solver read them each helm iteration); read-only."""
        return _grid(self.low, self.high, self.npts)

    def decision(self, index: int) -> float:
        """The grid point at `index` as the helm decides it (rounded to 9 decimals)."""
        return _decisions(self.low, self.high, self.npts)[index]

    def index_of(self, value: float) -> int:
        """The grid index nearest a value, clipped to the domain."""
        if self.npts == 1:
            return 0
        return int(np.clip(round((value - self.low) / self.delta), 0, self.npts - 1))


@functools.lru_cache(maxsize=256)
def _grid(low: float, high: float, npts: int) -> np.ndarray:
    grid = low + np.arange(npts) * ((high - low) / (npts - 1) if npts > 1 else 0.0)   # DomainVar.delta
    grid.setflags(write=False)
    return grid


@functools.lru_cache(maxsize=256)
def _decisions(low: float, high: float, npts: int) -> tuple[float, ...]:
    """Each grid point rounded to 9 decimals, made once per grid (the solver decides every helm iteration)."""
    return tuple(round(float(v), 9) for v in _grid(low, high, npts))


class IvPDomain(BaseModel):
    vars: list[DomainVar]

    def __contains__(self, name: str) -> bool:
        return any(v.name == name for v in self.vars)

    def var(self, name: str) -> DomainVar:
        for v in self.vars:
            if v.name == name:
                return v
        raise KeyError(f"'{name}' is not a domain variable")

    @property
    def names(self) -> list[str]:
        return [v.name for v in self.vars]

    def describe(self) -> str:
        """The IVPHELM_DOMAIN text."""
        return ":".join(f"{v.name},{v.low:g},{v.high:g},{v.npts}" for v in self.vars)


def parse_domain_line(text: str) -> DomainVar:
    """`name:low:high:npts[:optional]` or `name:low:high:delta=D` (commas work like colons)."""
    fields = [f.strip() for f in text.replace(",", ":").split(":")]
    if len(fields) not in (4, 5):
        raise ValueError(f"domain '{text}': expected name:low:high:npts[:optional]")
    optional = len(fields) == 5
    if optional and fields[4].lower() != "optional":
        raise ValueError(f"domain '{text}': fifth field must be 'optional'")
    name = fields[0]
    try:
        low, high = float(fields[1]), float(fields[2])
        if fields[3].lower().startswith("delta="):
            delta = float(fields[3][6:])
            if delta <= 0:
                raise ValueError
            npts = int((high - low) / delta) + 1
        else:
            npts = int(fields[3])
    except ValueError:
        raise ValueError(f"domain '{text}': low, high and npts/delta must be numbers") from None
    return DomainVar(name=name, low=low, high=high, npts=npts, optional=optional)
