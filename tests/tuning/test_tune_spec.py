"""Every mistake in a tuning spec is one error naming its key."""

import math

import pytest

from etobs._spec import SpecError
from etobs.cli.main import main
from etobs.tuning import parse_tune_spec
from tests.tuning.conftest import BASE, raw_tune


def params(**over):
    return {**BASE["parameters"], **over}


@pytest.mark.parametrize(
    ("over", "message"),
    [
        ({"parametrs": {}}, r"unknown key `parametrs`; allowed top-level keys: budget, .*parameters"),
        ({"parameters": None}, r"missing key `parameters`: expected a table of factory arguments to search"),
        ({"parameters": {}}, r"`parameters` must be a non-empty table"),
        (
            {"parameters": params(eps={"low": 10.0, "high": 1.0})},
            r"`parameters.eps` is an empty box: `low` = 10 > `high` = 1",
        ),
        (
            {"parameters": params(eps={"low": 0.0, "high": 1.0, "log": True})},
            r"`parameters.eps.low` must be > 0 with `log = true`; got 0",
        ),
        ({"parameters": params(eps={"low": 1.0})}, r"missing key `parameters.eps.high`: expected a number"),
        (
            {"parameters": params(eps={"low": 1.0, "high": 2.0, "colour": 1})},
            r"unknown key `parameters.eps.colour`; allowed keys of `parameters.eps`: choices, high, log, low, per",
        ),
        (
            {"parameters": params(eps={"low": 1.0, "high": 2.0, "per": "all"})},
            r"`parameters.eps.per` must be one of node, shared, scalar; got 'all'",
        ),
        (
            {"parameters": params(eps={"low": "1", "high": 2.0})},
            r"`parameters.eps.low` must be a number; got '1'",
        ),
        ({"parameters": params(ell={"choices": []})}, r"`parameters.ell.choices` must be a non-empty list"),
        ({"parameters": params(ell={"choices": [1.0], "low": 0.0})}, r"`parameters.ell.low` goes with a box"),
        (
            {"parameters": params(colour={"low": 0.0, "high": 1.0})},
            r"parameter `colour` \(parameters\) is not an argument of the factory 'robot_arm'",
        ),
        ({"parameters": params(c={"low": 0.0, "high": 1.0})}, r"`parameters.c` is also in `system.fixed`"),
        ({"budget": None}, r"missing key `budget`: expected a table"),
        ({"budget": {"kind": "simulated"}}, r"missing key `budget.error`: expected a number > 0"),
        (
            {"budget": {"kind": "best", "error": 1.0}},
            r"`budget.kind` must be one of simulated, certified; got 'best'",
        ),
        ({"budget": {"kind": "simulated", "error": 0}}, r"`budget.error` must be > 0; got 0"),
        (
            {"budget": {"kind": "certified", "error": 1.0}, "observer": None, "guarantees": None},
            r"`budget.kind = \"certified\"` needs `\[observer\]`",
        ),
        ({"search": {"trials": 0}}, r"`search.trials` must be >= 1; got 0"),
        ({"search": {"prune_share": 1.0}}, r"`search.prune_share` must be < 1"),
        ({"search": {"error_floor": 1.5}}, r"`search.error_floor` must be in \[0, 1\]"),
        ({"search": {"screen": "yes"}}, r"`search.screen` must be true or false; got 'yes'"),
        ({"validation": {"seed": 1}}, r"`validation.seed` must differ from `initial_states.seed` \(1\)"),
        (
            {"constraints": {"tau_min": 0.01}, "guarantees": {"noise": [0.0, 0.01]}},
            r"`constraints.tau_min` needs `guarantees.E`",
        ),
        ({"objective": {"error_quantile": 1.5}}, r"`objective.error_quantile` must be in \(0, 1\]; got 1.5"),
        ({"references": [{"name": "x"}]}, r"missing key `references\[0\].params`"),
        (
            {"references": [{"name": "x", "params": {"colour": 1}}]},
            r"parameter `colour` \(references\[0\].params\) is not an argument",
        ),
        (
            {
                "observers": [
                    {"name": "a", "structure": "robot_arm", "L": "paper", "c_v": 0.1, "c": [0.1, 0.1]}
                ]
            },
            r"give either `\[observer\]` \(one\) or `\[\[observers\]\]`",
        ),
        (
            {
                "observer": None,
                "observers": [{"structure": "robot_arm", "L": "paper", "c_v": 0.1, "c": [0.1, 0.1]}],
            },
            r"missing key `observers\[0\].name`",
        ),
        (
            {"observer": {"structure": "robot_arm", "c_v": 0.1, "c": [0.1, 0.1]}},
            r"missing key `observer.L`: expected 'design', 'paper' or a matrix",
        ),
    ],
)
def test_a_bad_spec_is_one_error_naming_the_key(over, message):
    with pytest.raises(SpecError, match=message):
        parse_tune_spec(raw_tune(**over))


def test_the_base_spec_is_valid():
    spec = parse_tune_spec(raw_tune())
    assert [p.name for p in spec.parameters] == ["sigma", "eps", "a"]
    assert spec.search.trials == 10 and spec.validation_seed == 11


def test_the_cli_says_it_in_one_line_with_exit_2(tmp_path, capsys):
    path = tmp_path / "tune.toml"
    path.write_text(
        '[system]\nfactory = "robot_arm"\n[parameters]\neps = { low = 5.0, high = 1.0 }\n'
        '[budget]\nkind = "simulated"\nerror = 1.0\n[initial_states]\nlow = [0.0, 0.0, 0.0, 0.0]\n'
        "high = [1.0, 1.0, 1.0, 1.0]\nruns = 2\nseed = 0\n[horizon]\nt_end = 1.0\n"
    )
    with pytest.raises(SystemExit) as exc:
        main(["tune", str(path), "--out", str(tmp_path / "out")])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert err == f"etobs: error: {path}: `parameters.eps` is an empty box: `low` = 5 > `high` = 1\n"


def test_sampled_rules_are_tuned_on_a_simulated_budget_and_say_what_certified_means():
    """Sampled rules have no proven error bound: a certified budget is refused at the start;
    a candidate's certificate says that it checked the continuous rules' conditions."""
    from etobs.tuning.evaluate import Evaluator

    system = {**BASE["system"], "fixed": {**BASE["system"]["fixed"], "sample_period": 0.005}}
    certified = parse_tune_spec(raw_tune(system=system, budget={"kind": "certified", "error": 12.0}))
    with pytest.raises(
        SpecError,
        match=r'`budget.kind` = "certified" needs Theorem 2\'s error bound, which is '
        r"not proven for sampled rules",
    ):
        Evaluator(certified, None, {})
    ev = Evaluator(parse_tune_spec(raw_tune(system=system)), None, {})
    figs = ev.certify(
        {"sigma": [600.0, 800.0], "eps": [10.0, 10.0], "a": [2.0, 2.0]}, next(iter(ev.gains), None)
    )
    assert figs.ok and "sampled rules (node 0 at T = 0.005 s, node 1 at T = 0.005 s)" in figs.assumptions
    assert math.isnan(figs.error_bound) and min(figs.tau) >= 0.005
