from pathlib import Path

import pytest

from etobs.experiments import parse_spec

FACTORY = f"{Path(__file__).with_name('factories.py')}:scalar"


def raw_spec(**over):
    raw = {
        "name": "tiny",
        "system": {"factory": FACTORY, "fixed": {}},
        "rows": [{"k": 1.0}, {"k": 2.0}],
        "scenarios": [{"name": "coarse", "eps": 0.01}, {"name": "fine", "eps": 0.001}],
        "initial_states": {"low": [-1.0], "high": [1.0], "runs": 5, "seed": 7},
        "horizon": {"t_end": 3.0},
        "metrics": {"transmissions_window": [0.0, 3.0], "error_window": [2.0, 3.0], "error_grid_step": 0.01},
        "execution": {"chunk_size": 2},
    }
    raw.update(over)
    return raw


@pytest.fixture
def tiny():
    return parse_spec(raw_spec())
