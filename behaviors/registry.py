"""Which behaviour types a `.bhv` file may name: the built-in ones and plug-ins.

A third-party package adds a behaviour with no edit of the helm by declaring an entry point in
the `behaviors.bhv` group, named as `.bhv` files name the type (the name is matched without
regard to case, as the helm does), pointing at an IvPBehavior subclass:

    [project.entry-points."behaviors.bhv"]
    BHV_Zigzag = "my_package.zigzag:BHV_Zigzag"

A built-in type cannot be replaced by a plug-in of the same name.
"""
from __future__ import annotations

from importlib import metadata

from .behavior import IvPBehavior
from .bhv_avoid_collision import BHV_AvoidCollision
from .bhv_constant_depth import BHV_ConstantDepth
from .bhv_constant_heading import BHV_ConstantHeading
from .bhv_constant_speed import BHV_ConstantSpeed
from .bhv_loiter import BHV_Loiter
from .bhv_op_region import BHV_OpRegion
from .bhv_station_keep import BHV_StationKeep
from .bhv_waypoint import BHV_Waypoint

ENTRY_POINT_GROUP = "behaviors.bhv"
BUILTIN_TYPES: dict[str, type[IvPBehavior]] = {
    cls.type_name.lower(): cls
    for cls in (BHV_Waypoint, BHV_StationKeep, BHV_ConstantSpeed, BHV_ConstantHeading, BHV_ConstantDepth,
                BHV_Loiter, BHV_OpRegion, BHV_AvoidCollision)
}


class PluginError(ValueError):
    """An entry point in the behaviour group that does not load as an IvPBehavior subclass."""


def _load(entry: metadata.EntryPoint) -> type[IvPBehavior]:
    try:
        cls = entry.load()
    except Exception as exc:   # a broken third-party package: say which entry point, keep the reason
        raise PluginError(f"behaviour plug-in '{entry.name}' ({entry.value}) does not load: {exc}") from exc
    if not (isinstance(cls, type) and issubclass(cls, IvPBehavior)):
        raise PluginError(f"behaviour plug-in '{entry.name}' ({entry.value}) is not an IvPBehavior subclass")
    return cls


def plugin_entries() -> list[metadata.EntryPoint]:
    return [e for e in metadata.entry_points(group=ENTRY_POINT_GROUP) if e.name.lower() not in BUILTIN_TYPES]


def behavior_class(type_name: str) -> type[IvPBehavior] | None:
    """The class for a `Behavior = <type_name>` line, or None when no type has that name."""
    low = type_name.lower()
    if low in BUILTIN_TYPES:
        return BUILTIN_TYPES[low]
    entry = next((e for e in plugin_entries() if e.name.lower() == low), None)
    return _load(entry) if entry is not None else None


def known_type_names() -> list[str]:
    """Every type name the helm accepts, built-in first (for error messages and docs)."""
    return [c.type_name for c in BUILTIN_TYPES.values()] + [e.name for e in plugin_entries()]
