"""A small tuning of the robot arm: short runs, few of them, a given E (no estimate runs)."""

import copy

import pytest

BASE = {
    "name": "arm",
    "system": {
        "factory": "robot_arm",
        "fixed": {
            "noise": True,
            "disturbance": True,
            "c": [0.001, 0.001],
            "b": [1.0, 1.0],
            "eta0": [10.0, 10.0],
        },
    },
    "parameters": {
        "sigma": {"low": 0.0, "high": 950.0},
        "eps": {"low": 1.0, "high": 1000.0, "log": True},
        "a": {"low": 0.5, "high": 10.0, "log": True, "per": "shared"},
    },
    "observer": {"structure": "robot_arm", "L": "paper", "c_v": 0.1, "c": [0.1, 0.1]},
    "guarantees": {"E": [30.0, 60.0], "noise": [0.0, 0.01], "disturbance": 0.0283},
    "budget": {"kind": "simulated", "error": 12.0},
    "search": {"trials": 10, "seed": 3, "batch": 4, "startup": 4},
    "validation": {"runs": 3, "seed": 11},
    "references": [{"name": "row 8", "params": {"a": [1.0, 1.0]}}],
    "initial_states": {"low": [0.0, 0.0, 0.0, 0.0], "high": [20.0, 10.0, 20.0, 10.0], "runs": 4, "seed": 1},
    "horizon": {"t_end": 4.0},
    "metrics": {"error_window": [3.0, 4.0], "error_grid_step": 0.01},
    "execution": {"chunk_size": 2},
}


def raw_tune(**over):
    """The base spec with top-level tables replaced (a value ``None`` removes the key)."""
    raw = copy.deepcopy(BASE)
    for k, v in over.items():
        if v is None:
            raw.pop(k, None)
        else:
            raw[k] = v
    return raw


@pytest.fixture
def cvxpy():
    return pytest.importorskip("cvxpy", reason="the design extra is not installed")
