"""Generic hybrid-system solvers; nothing here knows about observers or sensors."""

from etobs.hybrid.options import SaveAt, SolverOptions
from etobs.hybrid.reference import solve_reference
from etobs.hybrid.solution import GridMax, HybridArc, HybridSolution, JumpLog, JumpRow, SavedGrid
from etobs.hybrid.solver import solve
from etobs.hybrid.status import Status, status_message
from etobs.hybrid.system import BatchedSystem, HybridSystem

__all__ = [
    "BatchedSystem",
    "GridMax",
    "HybridArc",
    "HybridSolution",
    "HybridSystem",
    "JumpLog",
    "JumpRow",
    "SaveAt",
    "SavedGrid",
    "SolverOptions",
    "Status",
    "solve",
    "solve_reference",
    "status_message",
]
