"""BHV_ConstantDepth: hold one depth (a peak over the depth domain variable only)."""
from __future__ import annotations

from .bhv_constant_speed import OneVarPeak


class BHV_ConstantDepth(OneVarPeak):
    type_name = "BHV_ConstantDepth"
    default_name = "bhv_constantdepth"
    decision_var = "depth"
    value_param = "depth"
    peakwidth = 3.0
    basewidth = 100.0
    summitdelta = 50.0
