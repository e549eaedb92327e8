"""The paper's event-triggered estimator assembled as a hybrid system, its simulation and metrics."""

from etobs.estimation.cost import ModelCost, model_cost
from etobs.estimation.layout import StateLayout
from etobs.estimation.metrics import (
    input_transmission_counts,
    inter_event_times,
    max_estimation_error,
    min_inter_event_time,
    transmission_counts,
)
from etobs.estimation.problem import EstimationProblem
from etobs.estimation.result import EstimationResult, Trajectory
from etobs.estimation.simulate import simulate

__all__ = [
    "EstimationProblem",
    "EstimationResult",
    "ModelCost",
    "StateLayout",
    "Trajectory",
    "input_transmission_counts",
    "inter_event_times",
    "max_estimation_error",
    "min_inter_event_time",
    "model_cost",
    "simulate",
    "transmission_counts",
]
