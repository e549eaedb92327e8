"""Model objects: plant, observer, nodes, triggering rules, class-K functions, signals."""

from etobs.model.functions import Custom, KFunction, Linear, Power, Quadratic
from etobs.model.generalized import GeneralizedRule
from etobs.model.high_gain import high_gain_gain, high_gain_observer
from etobs.model.kalman import ekf_initial_state, extended_kalman_filter
from etobs.model.linear import linear_luenberger, linear_plant
from etobs.model.network import (
    BernoulliLoss,
    ConstantDelay,
    ExponentialDelay,
    GilbertElliottLoss,
    Link,
    Network,
    UniformDelay,
)
from etobs.model.node import InputNode, Node
from etobs.model.observer import Observer, luenberger
from etobs.model.plant import Plant
from etobs.model.python_control import python_control_plant
from etobs.model.rules import DynamicRule, PeriodicRule, RelativeRule, StaticRule, TriggerRule, send_on_delta
from etobs.model.sampled import Sampled
from etobs.model.signals import Constant, FunctionSignal, Signal, Sinusoid, Zero

__all__ = [
    "BernoulliLoss",
    "Constant",
    "ConstantDelay",
    "Custom",
    "DynamicRule",
    "ExponentialDelay",
    "FunctionSignal",
    "GeneralizedRule",
    "GilbertElliottLoss",
    "InputNode",
    "KFunction",
    "Linear",
    "Link",
    "Network",
    "Node",
    "Observer",
    "PeriodicRule",
    "Plant",
    "Power",
    "Quadratic",
    "RelativeRule",
    "Sampled",
    "Signal",
    "Sinusoid",
    "StaticRule",
    "TriggerRule",
    "UniformDelay",
    "Zero",
    "ekf_initial_state",
    "extended_kalman_filter",
    "high_gain_gain",
    "high_gain_observer",
    "linear_luenberger",
    "linear_plant",
    "luenberger",
    "python_control_plant",
    "send_on_delta",
]
