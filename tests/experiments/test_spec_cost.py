"""Specs that ask for more steps than the solver's limits allow are refused when parsed (issue 23).

A sweep over a horizon of ``t_end`` with ``solver.max_step`` takes at least ``t_end /
max_step`` steps per run; beyond ``solver.max_steps`` every run would spend its whole
step budget and stop with ``max_steps``, so the spec is refused in one line naming the
keys, before any run.
"""

import pytest

from etobs.experiments import SpecError, parse_spec
from etobs.experiments.compare_spec import parse_compare_spec
from etobs.hybrid.options import MAX_STEPS, SolverOptions, beyond_step_limit

from .conftest import raw_spec


def _sweep(t_end, **solver):
    return raw_spec(horizon={"t_end": t_end}, solver=solver)


def _compare(t_end, **solver):
    raw = {k: v for k, v in _sweep(t_end, **solver).items() if k not in ("rows", "scenarios")}
    raw["system"] = {"factory": raw["system"]["factory"], "params": {"k": 1.0}}
    raw["rules"] = [{"name": "base", "kind": "base"}]
    return raw


MESSAGE = (
    r"^`horizon.t_end` = 100000 needs at least 100000000 steps at `solver.max_step` = 0.001, more than "
    r"`solver.max_steps` = 2000000 \(every run would stop with status max_steps\); raise "
    r"`solver.max_steps` or `solver.max_step`, or shorten the horizon$"
)


@pytest.mark.parametrize("parse", [parse_spec, parse_compare_spec], ids=["sweep", "compare"])
def test_a_horizon_beyond_the_step_limit_is_refused_in_one_line(parse):
    # issue 23: a 1e5-s horizon ran for minutes per run before ending with max_steps
    raw = _sweep if parse is parse_spec else _compare
    with pytest.raises(SpecError, match=MESSAGE) as info:
        parse(raw(1e5, max_step=1e-3))
    assert "\n" not in str(info.value)
    parse(raw(1e5, max_step=1e-3, max_steps=10**8))  # raised to what it needs: accepted
    parse(raw(1e5))  # no max_step: no bound to refuse by (the step limit ends each run)


@pytest.mark.parametrize("parse", [parse_spec, parse_compare_spec], ids=["sweep", "compare"])
def test_the_refusal_is_exact_at_the_limit(parse):
    # max_step = 0.5: t_end = 1e6 takes exactly MAX_STEPS steps (accepted), half a step
    # more needs one more (refused)
    raw = _sweep if parse is parse_spec else _compare
    parse(raw(MAX_STEPS * 0.5, max_step=0.5))
    with pytest.raises(
        SpecError, match=r"needs at least 2000001 steps .* more than `solver.max_steps` = 2000000"
    ):
        parse(raw(MAX_STEPS * 0.5 + 0.5, max_step=0.5))


def test_beyond_step_limit_names_the_arguments_of_a_call():
    assert beyond_step_limit(10.0, SolverOptions(max_step=1.0, max_steps=10)) == ""
    assert beyond_step_limit(11.0, SolverOptions(max_step=1.0, max_steps=10)).startswith(
        "`t_end` = 11 needs at least 11 steps at `max_step` = 1, more than `max_steps` = 10"
    )
