"""BHV_ConstantHeading: hold one heading (a wrapped peak over course only)."""
from __future__ import annotations

from .bhv_constant_speed import OneVarPeak, peak_params
from .parameters import NUMBER, attr


class BHV_ConstantHeading(OneVarPeak):
    type_name = "BHV_ConstantHeading"
    default_name = "bhv_constantHeading"
    decision_var = "course"
    value_param = "heading"
    value_wrap = True
    params = (*peak_params("heading", wrap=True, peakwidth=10, basewidth=170, summitdelta=25),
              attr("complete_thresh", "complete_thresh", NUMBER, "0",
                   "complete once within this many degrees of the heading (0: never)"))

    def completed_by_mismatch(self, mismatch: float) -> bool:
        return mismatch < self.complete_thresh
