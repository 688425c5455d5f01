"""Which behaviour types a `.bhv` file may name: the entry points of the `behaviors.bhv` group.

Like the apps (`moosdb_py.apps`), the entry points alone say which behaviours exist: this package
registers its own in pyproject.toml, and a third-party package adds one, with no edit of the
helm, by declaring an entry point named as `.bhv` files name the type (matched without regard to
case, as the helm does) that points at an IvPBehavior subclass:

    [project.entry-points."behaviors.bhv"]
    BHV_Zigzag = "my_package.zigzag:BHV_Zigzag"

Classes are loaded when first named and kept; a name not seen before makes a fresh scan, so a
package installed while a process runs is found too.
"""
from __future__ import annotations

from importlib import metadata

from .behavior import IvPBehavior

ENTRY_POINT_GROUP = "behaviors.bhv"
_loaded: dict[str, type[IvPBehavior]] = {}


class PluginError(ValueError):
    """An entry point in the behaviour group that does not load as an IvPBehavior subclass."""


def entries() -> dict[str, metadata.EntryPoint]:
    """The group's entry points by lower-cased type name (the first of two of one name wins)."""
    found: dict[str, metadata.EntryPoint] = {}
    for entry in metadata.entry_points(group=ENTRY_POINT_GROUP):
        found.setdefault(entry.name.lower(), entry)
    return found


def _load(entry: metadata.EntryPoint) -> type[IvPBehavior]:
    try:
        cls = entry.load()
    except Exception as exc:   # a broken third-party package: say which entry point, keep the reason
        raise PluginError(f"behaviour plug-in '{entry.name}' ({entry.value}) does not load: {exc}") from exc
    if not (isinstance(cls, type) and issubclass(cls, IvPBehavior)):
        raise PluginError(f"behaviour plug-in '{entry.name}' ({entry.value}) is not an IvPBehavior subclass")
    return cls


def behavior_class(type_name: str) -> type[IvPBehavior] | None:
    """The class for a `Behavior = <type_name>` line, or None when no package registers that name."""
    low = type_name.lower()
    if low not in _loaded:
        entry = entries().get(low)
        if entry is None:
            return None
        _loaded[low] = _load(entry)
    return _loaded[low]


def behavior_types() -> dict[str, type[IvPBehavior]]:
    """Every registered type that loads, by lower-cased name (moos-lint and the docs ask). A broken
    plug-in is left out here; it is an error only where a .bhv file names it."""
    types = {}
    for name in entries():
        try:
            types[name] = behavior_class(name)
        except PluginError:
            continue
    return types


def known_type_names() -> list[str]:
    """Every registered type name, for error messages; empty means the package is not installed."""
    return sorted(entry.name for entry in entries().values())
