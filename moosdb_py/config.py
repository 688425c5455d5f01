"""ProcessConfig parameters, declared once per app: typed readers, defaults, docs and the unhandled warning.

An app lists its parameters as `Param(name, type, default, doc)`; `MOOSApp` warns about every line
of its block that is neither declared nor one of the keys every MOOSApp reads (`MOOS_APP_KEYS`),
`Params.read` gives the typed values, `Params.table` the docs table, and moos-lint can read the
same declaration through the `moosdb_py.apps` entry points. Values follow moosdb_py.formats.

The readers take anything with `get(key, default)` whose keys are lower-case parameter names: a
`moosdb_py.mission.ProcessConfig` (case-insensitive, last line wins) or a plain dict, which keeps
the vehicle models testable without a mission.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any, Protocol

from . import formats
from .formats import FormatError


class ConfigLike(Protocol):
    def get(self, key: str, default=None): ...


log = logging.getLogger("moosdb_py.config")

# What CMOOSApp and AppCastingMOOSApp read from every block (MaxAppTick caps the rate of an app woken by
# mail; this base runs every app at AppTick, so it is accepted and has no effect).
MOOS_APP_KEYS = frozenset({"apptick", "commstick", "maxapptick", "maxappticks", "iteratemode", "verbose", "debug",
                           "sortmailbytime", "catchcommandmessages", "app_logging", "term_reporting",
                           "max_appcast_events", "max_appcast_run_warnings"})


class ConfigValueError(ValueError):
    """A bad parameter value; `key` is the parameter, so the app can point at its file:line."""

    def __init__(self, what: str, message: str):
        self.key = what.split()[0]
        super().__init__(f"{what}: {message}")


def parse_bool(text: str, what: str) -> bool:
    """A MOOS boolean, with an error naming `what`."""
    try:
        return formats.parse_bool(text)
    except FormatError as err:
        raise ConfigValueError(what, str(err)) from None


def parse_float(text: str, what: str, lo: float | None = None, hi: float | None = None) -> float:
    """A MOOS number within [lo, hi], with an error naming `what`."""
    try:
        value = formats.parse_number(text)
    except FormatError as err:
        raise ConfigValueError(what, str(err)) from None
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        raise ConfigValueError(what, f"{value:g} is outside [{lo}, {hi}]")
    return value


@dataclass(frozen=True)
class Param:
    """One ProcessConfig parameter: `kind` is bool, int, float, str or list (every line of a repeatable key)."""

    name: str
    kind: type
    default: Any
    doc: str
    lo: float | None = None
    hi: float | None = None

    def parse(self, text: str) -> Any:
        if self.kind is bool:
            return parse_bool(text, self.name)
        if self.kind in (int, float):
            value = parse_float(text, self.name, self.lo, self.hi)
            if self.kind is int and not value.is_integer():
                raise ConfigValueError(self.name, f"expected a whole number, got {text!r}")
            return self.kind(value)
        return str(text).strip()

    def read(self, cfg: ConfigLike) -> Any:
        """The value in `cfg`, or the default when the key is absent or blank."""
        if self.kind is list:
            values = cfg.get_all(self.name) if hasattr(cfg, "get_all") else _as_list(cfg.get(self.name, None))
            return [str(v).strip() for v in values if str(v).strip()]
        text = cfg.get(self.name, None)
        if text is None or str(text).strip() == "":
            return self.default
        return self.parse(text)

    def default_text(self) -> str:
        if self.default is None or self.default == []:
            return ""
        if isinstance(self.default, bool):
            return formats.format_bool(self.default)
        if isinstance(self.default, float):
            return formats.format_number(self.default, 6)
        return str(self.default)


def _as_list(value) -> list:
    return [] if value is None else list(value) if isinstance(value, (list, tuple)) else [value]


class Params:
    """An app's declared parameters, in the order its docs list them."""

    def __init__(self, *params: Param):
        self.params = params
        self.by_name = {p.name.lower(): p for p in params}

    def __iter__(self):
        """The declarations in order (moos-lint checks a block's lines against them)."""
        return iter(self.params)

    def __getitem__(self, name: str) -> Param:
        """The declaration of `name`, any case."""
        return self.by_name[name.lower()]

    @property
    def names(self) -> frozenset[str]:
        return frozenset(self.by_name)

    def read(self, cfg: ConfigLike) -> dict[str, Any]:
        """{name: typed value} for every declared parameter (lower-case names)."""
        return {key: param.read(cfg) for key, param in self.by_name.items()}

    def unhandled(self, cfg) -> list[str]:
        """`file:line: unhandled parameter 'key'` for each line that is neither declared nor a MOOSApp key."""
        return [f"{entry.source}: unhandled parameter {entry.key!r}" for entry in getattr(cfg, "entries", [])
                if entry.key.lower() not in self.by_name and entry.key.lower() not in MOOS_APP_KEYS]

    def warn_unhandled(self, cfg) -> None:
        """Log every unused line of the block: a misspelt key would otherwise fall back to its default unseen."""
        for warning in self.unhandled(cfg):
            log.warning("%s", warning)

    def table(self) -> str:
        """The docs' parameter table (docs/<app>.md holds it verbatim; a test checks they agree)."""
        rows = ["| Parameter | Type | Default | Meaning |", "|---|---|---|---|"]
        for p in self.params:
            kind = "repeatable" if p.kind is list else p.kind.__name__
            if p.lo is not None or p.hi is not None:
                kind += f" in [{'' if p.lo is None else formats.format_number(p.lo, 6)}, " \
                        f"{'' if p.hi is None else formats.format_number(p.hi, 6)}]"
            default = p.default_text()
            rows.append(f"| `{p.name}` | {kind} | {f'`{default}`' if default else ''} | {p.doc} |")
        return "\n".join(rows) + "\n"


def read_params(config, reader):
    """`reader(config)`, with a bad value reported at its mission-file line (`file:line: key: ...`)."""
    try:
        return reader(config)
    except ConfigValueError as err:
        entry = config.entry(err.key) if hasattr(config, "entry") else None
        if entry is None:
            raise
        raise entry.source.error(str(err)) from None


def warn_unhandled(config, known: set[str] | frozenset[str]) -> None:
    """Log every line of the block whose key is not in `known` (for apps whose keys are not all Params)."""
    Params(*(Param(k, str, None, "") for k in known)).warn_unhandled(config)


def config_float(cfg: ConfigLike, key: str, default: float, lo: float | None = None,
                 hi: float | None = None) -> float:
    return Param(key, float, default, "", lo, hi).read(cfg)


def config_bool(cfg: ConfigLike, key: str, default: bool) -> bool:
    return Param(key, bool, default, "").read(cfg)


def config_str(cfg: ConfigLike, key: str, default: str) -> str:
    return Param(key, str, default, "").read(cfg)
