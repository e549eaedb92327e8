"""The public API of etobs, each name written once: ``etobs/__init__.py`` reads this file.

A type checker reads it as the package's interface; at run time ``etobs.__getattr__``
imports each name from the module given here on its first use (PEP 562).
"""

from etobs._spec import factory as factory
from etobs._version import __version__ as __version__
from etobs.errors import EtobsError as EtobsError
from etobs.errors import InputError as InputError
from etobs.errors import InputTypeError as InputTypeError
from etobs.errors import ModelError as ModelError
from etobs.errors import PerformanceWarning as PerformanceWarning
from etobs.estimation import EstimationProblem as EstimationProblem
from etobs.estimation import EstimationResult as EstimationResult
from etobs.estimation import Trajectory as Trajectory
from etobs.estimation import input_transmission_counts as input_transmission_counts
from etobs.estimation import inter_event_times as inter_event_times
from etobs.estimation import max_estimation_error as max_estimation_error
from etobs.estimation import min_inter_event_time as min_inter_event_time
from etobs.estimation import simulate as simulate
from etobs.estimation import transmission_counts as transmission_counts
from etobs.hybrid import HybridSystem as HybridSystem
from etobs.hybrid import SaveAt as SaveAt
from etobs.hybrid import SolverOptions as SolverOptions
from etobs.hybrid import Status as Status
from etobs.model import Constant as Constant
from etobs.model import Custom as Custom
from etobs.model import DynamicRule as DynamicRule
from etobs.model import FunctionSignal as FunctionSignal
from etobs.model import InputNode as InputNode
from etobs.model import KFunction as KFunction
from etobs.model import Linear as Linear
from etobs.model import Link as Link
from etobs.model import Network as Network
from etobs.model import Node as Node
from etobs.model import Observer as Observer
from etobs.model import PeriodicRule as PeriodicRule
from etobs.model import Plant as Plant
from etobs.model import Power as Power
from etobs.model import Quadratic as Quadratic
from etobs.model import RelativeRule as RelativeRule
from etobs.model import Sampled as Sampled
from etobs.model import Sinusoid as Sinusoid
from etobs.model import StaticRule as StaticRule
from etobs.model import TriggerRule as TriggerRule
from etobs.model import Zero as Zero
from etobs.model import linear_luenberger as linear_luenberger
from etobs.model import linear_plant as linear_plant
from etobs.model import luenberger as luenberger
from etobs.model import python_control_plant as python_control_plant
