"""etobs: decentralized event-triggered state estimation of nonlinear systems.

The public API re-exports the model objects, the estimation front door
:func:`simulate` and its metrics, and the solver settings. Plotting lives in
:mod:`etobs.plot` (optional extra) and is not imported here.

The names are imported on first use (PEP 562), so that ``import etobs.runtime.sensor``
on a small device needs neither numpy nor scipy.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from etobs._version import __version__
from etobs.errors import EtobsError, InputError, InputTypeError, ModelError

#: Public name -> the module that defines it (imported when the name is first used).
_EXPORTS = {
    "EstimationProblem": "etobs.estimation",
    "EstimationResult": "etobs.estimation",
    "Trajectory": "etobs.estimation",
    "input_transmission_counts": "etobs.estimation",
    "inter_event_times": "etobs.estimation",
    "max_estimation_error": "etobs.estimation",
    "min_inter_event_time": "etobs.estimation",
    "simulate": "etobs.estimation",
    "transmission_counts": "etobs.estimation",
    "HybridSystem": "etobs.hybrid",
    "SaveAt": "etobs.hybrid",
    "SolverOptions": "etobs.hybrid",
    "Status": "etobs.hybrid",
    "Constant": "etobs.model",
    "Custom": "etobs.model",
    "DynamicRule": "etobs.model",
    "FunctionSignal": "etobs.model",
    "InputNode": "etobs.model",
    "KFunction": "etobs.model",
    "Linear": "etobs.model",
    "Link": "etobs.model",
    "Network": "etobs.model",
    "Node": "etobs.model",
    "Observer": "etobs.model",
    "PeriodicRule": "etobs.model",
    "Plant": "etobs.model",
    "Power": "etobs.model",
    "Quadratic": "etobs.model",
    "RelativeRule": "etobs.model",
    "Sinusoid": "etobs.model",
    "StaticRule": "etobs.model",
    "TriggerRule": "etobs.model",
    "Zero": "etobs.model",
    "luenberger": "etobs.model",
    "linear_luenberger": "etobs.model",
    "linear_plant": "etobs.model",
    "python_control_plant": "etobs.model",
    "factory": "etobs._spec",
}

if TYPE_CHECKING:
    from etobs._spec import factory
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
    from etobs.hybrid import (
        HybridSystem,
        SaveAt,
        SolverOptions,
        Status,
    )
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
        linear_luenberger,
        linear_plant,
        luenberger,
        python_control_plant,
    )


#: Subpackages reachable as attributes (``etobs.model``), imported on first use.
_SUBPACKAGES = frozenset(
    {"cli", "design", "estimation", "examples", "experiments", "hybrid", "model", "plot", "runtime"}
)


def __getattr__(name: str) -> Any:
    if name in _SUBPACKAGES:
        return importlib.import_module(f"etobs.{name}")
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'etobs' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_EXPORTS])


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
    "factory",
    "input_transmission_counts",
    "inter_event_times",
    "linear_luenberger",
    "linear_plant",
    "luenberger",
    "max_estimation_error",
    "min_inter_event_time",
    "python_control_plant",
    "simulate",
    "transmission_counts",
]
