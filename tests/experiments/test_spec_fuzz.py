"""Generated specs: each is either a valid spec or an InputError naming the key, never another
exception (the audit of issue 14 found tracebacks for integers beyond float range, rule
kinds of the wrong type, deep nesting, ...).

Valid sweep and comparison specs are changed at random places: a value replaced by one of
another type (numbers of every size, strings, booleans, dates, arrays, tables), a key
deleted or an unknown key added. Everything the CLI does with a spec before any run is
done: parse, check the factory's arguments (a comparison builds every entry's problem),
and write the resolved spec and the result keys as JSON.
"""

import copy
import datetime
import json
import re
import string
import warnings

from hypothesis import given, settings
from hypothesis import strategies as st

from etobs.errors import EtobsError, InputError
from etobs.experiments.common import normalize
from etobs.experiments.compare_spec import parse_compare_spec
from etobs.experiments.spec import parse_spec
from etobs.experiments.store import task_key

from .conftest import raw_spec

COMPARE = {
    "name": "fuzz",
    "system": {"factory": "tests.estimation.linear:factory", "params": {"eps": 0.01}},
    "initial_states": {"low": [-1.0, -1.0], "high": [1.0, 1.0], "runs": 2, "seed": 4},
    "horizon": {"t_end": 2.0},
    "metrics": {"transmissions_window": [0.0, 2.0], "error_window": [1.0, 2.0], "error_grid_step": 0.01},
    "solver": {"rtol": 1e-8, "max_jumps": 1000},
    "execution": {"chunk_size": 2, "backend": "engine"},
    "rules": [
        {"name": "base", "kind": "base"},
        {"name": "dynamic", "kind": "dynamic", "sigma": [1.0], "eps": 0.01},
        {"name": "periodic", "kind": "periodic", "period": 0.05},
        {"name": "relative", "kind": "relative", "rho": 0.1, "eps": 0.01},
    ],
    "networks": [
        {"name": "ideal"},
        {"name": "lossy", "delay": {"uniform": [0.0, 0.01]}, "loss": 0.1, "capacity": 4, "seed": 1},
    ],
}
SWEEP = raw_spec(solver={"rtol": 1e-8}, grid={"k": [1.0, 2.0]}, rows=None)
del SWEEP["rows"]

KEYS = st.text(alphabet=string.ascii_letters + "_-.` \n'", min_size=1, max_size=8)
SCALARS = (
    st.booleans()
    | st.integers()
    | st.integers(min_value=10**300, max_value=10**400)
    | st.floats()
    | st.text(max_size=8)
    | st.datetimes(min_value=datetime.datetime(1900, 1, 1)).map(lambda d: d.replace(microsecond=0))
)
VALUES = st.recursive(
    SCALARS,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(KEYS, inner, max_size=3),
    max_leaves=8,
)


def paths(node, prefix=()):
    """Every place in a spec: a key of a table or an item of an array."""
    if isinstance(node, dict):
        for k, v in node.items():
            yield (*prefix, k)
            yield from paths(v, (*prefix, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield (*prefix, i)
            yield from paths(v, (*prefix, i))


@st.composite
def changed(draw, base):
    """``base`` changed in 1 to 3 places, and the names of the keys changed."""
    raw = copy.deepcopy(base)
    names = set()
    for _ in range(draw(st.integers(1, 3))):
        where = draw(st.sampled_from(sorted(paths(raw), key=repr)))
        *parent_path, last = where
        parent = raw
        for p in parent_path:
            parent = parent[p]
        action = draw(st.sampled_from(["replace", "delete", "add"]))
        names |= {p for p in where if isinstance(p, str)}
        if action == "replace" or (action == "delete" and isinstance(parent, list)):
            parent[last] = draw(VALUES)
        elif action == "delete":
            del parent[last]
        elif isinstance(parent[last], dict):
            key = draw(KEYS)
            parent[last][key] = draw(VALUES)
            names.add(key)
        else:
            parent[last] = draw(VALUES)
        if not isinstance(raw, dict):
            break
    return raw, names


def valid_or_named(parse, raw, names):
    """Parse and check ``raw`` as the CLI does before any run; an error must name a changed key."""
    try:
        spec = parse(raw)
        with warnings.catch_warnings():  # a theorem condition that fails warns; here only errors count
            warnings.simplefilter("ignore")
            spec.check()
        # what the pipeline writes before any run
        json.dumps(normalize({"as_given": spec.raw, "resolved": spec.resolved()}, ints_as_floats=False))
        for g in range(spec.n_groups):
            task_key(spec, g)
    except InputError as exc:
        message = str(exc)
        assert re.search(r"`[^`]*`|'[^']*'", message), message  # it quotes a key or a value
        assert any(name in message for name in names), (names, message)
    except EtobsError as exc:  # an InputTypeError: an input check that a spec key should have done
        raise AssertionError(f"not a SpecError naming the key: {exc!r}") from exc


@settings(max_examples=150, deadline=None)
@given(changed(SWEEP))
def test_generated_sweep_specs_are_valid_or_name_the_key(case):
    valid_or_named(parse_spec, *case)


@settings(max_examples=150, deadline=None)
@given(changed(COMPARE))
def test_generated_compare_specs_are_valid_or_name_the_key(case):
    valid_or_named(parse_compare_spec, *case)


DEPLOY = {
    "name": "fuzz",
    "system": {"factory": "tests.estimation.linear:factory", "params": {"eps": 0.01}},
    "runtime": {
        "period": 0.01,
        "duration": 1.0,
        "time_scale": 2.0,
        "host": "127.0.0.1",
        "port": 0,
        "http_port": 0,
        "http_host": "127.0.0.1",
        "dt": 0.001,
        "hold_back": 0.05,
        "secret_file": "secret.key",
        "state_file": "marks.state",
        "max_value": 1e6,
        "transport": "mqtt",
        "broker": "127.0.0.1:1883",
        "topic": "etobs/fuzz",
    },
    "plant": {"x0": [1.0, 0.0]},
}


@settings(max_examples=150, deadline=None)
@given(changed(DEPLOY))
def test_generated_deployment_specs_are_valid_or_name_the_key(case):
    # parse_deployment (and the factory it names) never raises anything but an InputError
    # naming a changed key; it now also refuses what no key takes (check_tree) when the
    # spec is given as a dictionary, as parse_spec does
    from pathlib import Path

    from etobs.runtime.deployment import parse_deployment

    raw, names = case
    try:
        dep = parse_deployment(raw, Path("/nonexistent"))
        dep.problem()
    except InputError as exc:
        message = str(exc)
        assert re.search(r"`[^`]*`|'[^']*'", message), message
        assert any(name in message for name in names), (names, message)
    except EtobsError as exc:
        raise AssertionError(f"not a SpecError naming the key: {exc!r}") from exc
