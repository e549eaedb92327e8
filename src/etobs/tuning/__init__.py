"""Certified tuning: the fewest transmissions for an accuracy budget, with the guarantees holding."""

from etobs.tuning.result import TuningResult
from etobs.tuning.spec import TuneSpec, load_tune_spec, parse_tune_spec
from etobs.tuning.tune import tune

__all__ = ["TuneSpec", "TuningResult", "load_tune_spec", "parse_tune_spec", "tune"]
