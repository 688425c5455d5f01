"""The forecaster kinds a user can pick (``--model``), without importing any of them."""

LEARNED_KINDS = ("ltc-rk4", "ltc-euler", "ltc-fused", "lstm")
BASELINE_KINDS = ("persistence", "constant-velocity", "constant-velocity-growth", "physics", "physics-corrected")
KINDS = LEARNED_KINDS + BASELINE_KINDS
# The kind the report found best on the out-of-distribution split (docs/forecaster-report.md).
DEFAULT_MODEL = "ltc-fused"
