"""Monte-Carlo sweeps: validated specs, executors, atomic persistence, paper reproduction."""

from etobs.experiments.spec import SpecError, SweepSpec, load_spec, parse_spec
from etobs.experiments.sweep import SweepResult, collect, run_sweep

__all__ = ["SpecError", "SweepResult", "SweepSpec", "collect", "load_spec", "parse_spec", "run_sweep"]
