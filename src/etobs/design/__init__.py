"""Observer design and the paper's guarantees: LMI gains, ISS gains, certificates."""

from etobs.design.certificate import Certificate, Condition, NodeNumbers, certify
from etobs.design.hypotheses import Region, runs_leaving
from etobs.design.iss import QuadraticISS, even_split, quadratic_iss_gains
from etobs.design.lmi import ObserverGain, check_gain, observer_gain, slope_vertices
from etobs.design.proposals import RuleProposal, propose_rules
from etobs.design.rates import RateEstimate, estimate_output_rate, sample_output_rate

__all__ = [
    "Certificate",
    "Condition",
    "NodeNumbers",
    "ObserverGain",
    "QuadraticISS",
    "RateEstimate",
    "Region",
    "RuleProposal",
    "certify",
    "check_gain",
    "estimate_output_rate",
    "even_split",
    "observer_gain",
    "propose_rules",
    "quadratic_iss_gains",
    "runs_leaving",
    "sample_output_rate",
    "slope_vertices",
]
