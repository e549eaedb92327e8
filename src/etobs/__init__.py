"""etobs: decentralized event-triggered state estimation of nonlinear systems.

The public API re-exports the model objects, the estimation front door
:func:`simulate` and its metrics, and the solver settings. Plotting lives in
:mod:`etobs.plot` (optional extra) and is not imported here.
"""

from etobs.errors import EtobsError, InputError, InputTypeError, ModelError
from etobs.estimation import (
    EstimationProblem,
    EstimationResult,
    Trajectory,
    input_transmission_counts,
    inter_event_times,
    max_estimation_error,
    min_inter_event_time,
    simulate,
    transmission_counts,
)
from etobs.hybrid import HybridSystem, SaveAt, SolverOptions, Status
from etobs.model import (
    Constant,
    Custom,
    DynamicRule,
    FunctionSignal,
    InputNode,
    KFunction,
    Linear,
    Link,
    Network,
    Node,
    Observer,
    PeriodicRule,
    Plant,
    Power,
    Quadratic,
    RelativeRule,
    Sinusoid,
    StaticRule,
    TriggerRule,
    Zero,
    luenberger,
)

__version__ = "0.1.0"

__all__ = [
    "Constant",
    "Custom",
    "DynamicRule",
    "EstimationProblem",
    "EstimationResult",
    "EtobsError",
    "FunctionSignal",
    "HybridSystem",
    "InputError",
    "InputNode",
    "InputTypeError",
    "KFunction",
    "Linear",
    "Link",
    "ModelError",
    "Network",
    "Node",
    "Observer",
    "PeriodicRule",
    "Plant",
    "Power",
    "Quadratic",
    "RelativeRule",
    "SaveAt",
    "Sinusoid",
    "SolverOptions",
    "StaticRule",
    "Status",
    "Trajectory",
    "TriggerRule",
    "Zero",
    "__version__",
    "input_transmission_counts",
    "inter_event_times",
    "luenberger",
    "max_estimation_error",
    "min_inter_event_time",
    "simulate",
    "transmission_counts",
]
