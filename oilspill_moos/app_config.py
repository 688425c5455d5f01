"""Reading typed values out of a ProcessConfig block, with errors that name the parameter.

The functions take anything with `get(key, default)` whose keys are the lower-case
parameter names: a `moosdb_py.mission.ProcessConfig` (case-insensitive, last one
wins) or a plain dict, which keeps the vehicle models testable without a mission.
"""
from __future__ import annotations

import logging
from typing import Protocol

from moosdb_py import formats
from moosdb_py.formats import FormatError


class ConfigLike(Protocol):
    def get(self, key: str, default=None): ...


log = logging.getLogger("oilspill_moos.app_config")

# Parameters every MOOS app's block may hold; they are read by the MOOSApp base.
MOOS_APP_KEYS = frozenset({"apptick", "commstick", "maxappticks", "iteratemode", "verbose", "debug"})

class ConfigValueError(ValueError):
    """A bad parameter value; `key` is the parameter, so the app can point at its file:line."""

    def __init__(self, what: str, message: str):
        self.key = what.split()[0]
        super().__init__(f"{what}: {message}")


def read_params(config, reader):
    """`reader(config)`, with a bad value reported at its mission-file line (`file:line: key: ...`)."""
    try:
        return reader(config)
    except ConfigValueError as err:
        entry = config.entry(err.key) if hasattr(config, "entry") else None
        if entry is None:
            raise
        raise entry.source.error(str(err)) from None


def unhandled_entries(config, known: set[str] | frozenset[str]) -> list[str]:
    """`file:line: key` for each parameter of the block that the app does not use."""
    return [f"{entry.source}: unhandled parameter {entry.key!r}" for entry in getattr(config, "entries", [])
            if entry.key.lower() not in known and entry.key.lower() not in MOOS_APP_KEYS]


def warn_unhandled(config, known: set[str] | frozenset[str]) -> None:
    """Log every unused parameter of the block: a misspelt key would otherwise fall back to its default unseen."""
    for warning in unhandled_entries(config, known):
        log.warning("%s", warning)


def parse_bool(text: str, what: str) -> bool:
    """A MOOS boolean (moosdb_py.formats), with an error naming `what`."""
    try:
        return formats.parse_bool(text)
    except FormatError as err:
        raise ConfigValueError(what, str(err)) from None


def parse_float(text: str, what: str, lo: float | None = None, hi: float | None = None) -> float:
    """A MOOS number (moosdb_py.formats) within [lo, hi], with an error naming `what`."""
    try:
        value = formats.parse_number(text)
    except FormatError as err:
        raise ConfigValueError(what, str(err)) from None
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        raise ConfigValueError(what, f"{value:g} is outside [{lo}, {hi}]")
    return value


def config_float(cfg: ConfigLike, key: str, default: float, lo: float | None = None,
                 hi: float | None = None) -> float:
    text = cfg.get(key, None)
    if text is None or str(text).strip() == "":
        return default
    return parse_float(text, key, lo, hi)


def config_bool(cfg: ConfigLike, key: str, default: bool) -> bool:
    text = cfg.get(key, None)
    if text is None or str(text).strip() == "":
        return default
    return parse_bool(text, key)


def config_str(cfg: ConfigLike, key: str, default: str) -> str:
    text = cfg.get(key, None)
    if text is None or str(text).strip() == "":
        return default
    return str(text).strip()

