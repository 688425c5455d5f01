"""BHV_ConstantSpeed and the shared one-variable peak objective it (and BHV_ConstantHeading) build."""
from __future__ import annotations

from .behavior import IvPBehavior, parse_number
from .ivp_function import IvPFunction
from .zaic import PeakComponent, zaic_peak


class OneVarPeak(IvPBehavior):
    """A behaviour that wants one domain value: a ZAIC peak over that variable alone."""

    decision_var = "speed"
    value_param = "speed"
    value_wrap = False
    peakwidth = 0.0
    basewidth = 0.0
    summitdelta = 0.0
    # These behaviours time out at once unless given a `duration` (or `duration = no-time-limit`),
    # as in MOOS-IvP: they are meant to be bounded in time.
    default_duration = 0.0

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.desired: float | None = None
        self.peakwidth, self.basewidth, self.summitdelta = (type(self).peakwidth, type(self).basewidth,
                                                            type(self).summitdelta)
        self.domain_vars = (self.decision_var,)
        self.duration.limit = self.default_duration

    def set_param(self, key: str, value: str) -> bool:
        if key == self.value_param:
            self.desired = parse_number(value, key, 0 if not self.value_wrap else None)
        elif key == "peakwidth":
            self.peakwidth = parse_number(value, key, 0)
        elif key == "basewidth":
            self.basewidth = parse_number(value, key, 0)
        elif key == "summitdelta":
            self.summitdelta = parse_number(value, key, 0)
        else:
            return False
        return True

    def on_run_state(self) -> IvPFunction | None:
        if self.desired is None:
            self.post("BHV_WARNING", f"{self.name}: no {self.value_param} set", repeatable=True)
            return None
        var = self.domain.var(self.decision_var)
        summit = self.desired % 360.0 if self.value_wrap else min(self.desired, var.high)
        peak = PeakComponent(summit, self.peakwidth, self.basewidth, self.summitdelta, 0.0, 100.0)
        return IvPFunction((self.decision_var,), zaic_peak(var, [peak], value_wrap=self.value_wrap), self.pwt)

    def macro(self, name: str):
        if name.upper() == self.value_param.upper():
            return self.desired
        return super().macro(name)


class BHV_ConstantSpeed(OneVarPeak):
    """Hold one speed (a peak over speed only); usually with a `duration`."""

    type_name = "BHV_ConstantSpeed"
    default_name = "bhv_constant_speed"
    basewidth = 0.2
