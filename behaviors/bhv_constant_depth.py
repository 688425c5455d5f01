"""BHV_ConstantDepth: hold one depth (a peak over the depth domain variable only)."""
from __future__ import annotations

from .bhv_constant_speed import OneVarPeak, peak_params


class BHV_ConstantDepth(OneVarPeak):
    type_name = "BHV_ConstantDepth"
    default_name = "bhv_constantdepth"
    decision_var = "depth"
    value_param = "depth"
    params = peak_params("depth", wrap=False, peakwidth=3, basewidth=100, summitdelta=50)
