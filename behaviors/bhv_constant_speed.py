"""BHV_ConstantSpeed and the shared one-variable peak objective it (and BHV_ConstantHeading) build."""
from __future__ import annotations

from .behavior import IvPBehavior
from .geometry import fmt_num
from .ivp_function import IvPFunction
from .parameters import NON_NEGATIVE, NUMBER, ParamSpec, Parser, attr
from .zaic import PeakComponent, zaic_peak


def _variable_name(value: str, key: str) -> str:
    if any(c.isspace() for c in value):
        raise ValueError(f"{key} must be a MOOS variable name without blanks, got '{value}'")
    return value


def peak_params(value_param: str, wrap: bool, peakwidth: float, basewidth: float,
                summitdelta: float) -> tuple[ParamSpec, ...]:
    """The desired value, the peak's shape (with the type's own defaults) and the mismatch report."""
    return (
        attr(value_param, "desired", NUMBER if wrap else NON_NEGATIVE, doc=f"the desired {value_param}"),
        attr("peakwidth", "peakwidth", NON_NEGATIVE, fmt_num(peakwidth), "width of the flat top"),
        attr("basewidth", "basewidth", NON_NEGATIVE, fmt_num(basewidth), "width of each falling side"),
        attr("summitdelta", "summitdelta", NON_NEGATIVE, fmt_num(summitdelta), "utility drop across the top"),
        attr(f"{value_param}_mismatch_var", "mismatch_var", Parser("variable", _variable_name), "",
             f"variable for |NAV_{value_param.upper()} - {value_param}| each running iteration"
             + (" (the smaller angle)" if wrap else "")),
    )


class OneVarPeak(IvPBehavior):
    """A behaviour that wants one domain value: a ZAIC peak over that variable alone."""

    decision_var = "speed"
    value_param = "speed"
    value_wrap = False
    # These behaviours time out at once unless given a `duration` (or `duration = no-time-limit`),
    # as in MOOS-IvP: they are meant to be bounded in time.
    default_duration = 0.0

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.desired: float | None = None
        self.domain_vars = (self.decision_var,)
        self.duration.limit = self.default_duration

    def mismatch(self) -> float | None:
        """How far ownship is from the desired value (NAV_<VALUE>), or None when not known."""
        now = self.info.number(f"NAV_{self.value_param.upper()}")
        if now is None:
            return None
        delta = abs(now - self.desired)
        return min(delta % 360.0, 360.0 - delta % 360.0) if self.value_wrap else delta

    def completed_by_mismatch(self, mismatch: float) -> bool:
        """BHV_ConstantHeading's complete_thresh; the others never complete this way."""
        return False

    def on_run_state(self) -> IvPFunction | None:
        if self.desired is None:
            self.post("BHV_WARNING", f"{self.name}: no {self.value_param} set", repeatable=True)
            return None
        mismatch = self.mismatch()
        if mismatch is not None and self.mismatch_var:
            self.post(self.mismatch_var, round(mismatch, 6))
        if mismatch is not None and self.completed_by_mismatch(mismatch):
            self.set_complete()
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
    params = peak_params("speed", wrap=False, peakwidth=0, basewidth=0.2, summitdelta=0)
