import json
import re
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("cvxpy")

from etobs.cli.main import main

SPEC = """
[system]
factory = "robot_arm"
params = {{ sigma = [600.0, {sigma2}], c = [0.001, 0.001], eps = [10.0, 10.0] }}
[observer]
structure = "robot_arm"
L = "paper"
c_v = 0.1
c = [0.1, 0.1]
[guarantees]
E = [10.0, 20.0]
noise = [0.0, 0.01]
"""


def write(tmp_path, sigma2=800.0, extra=""):
    path = tmp_path / "check.toml"
    path.write_text(SPEC.format(sigma2=sigma2) + extra)
    return str(path)


def test_check_prints_the_certificate(tmp_path, capsys):
    assert main(["check", write(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "OK   sigma*c < 1 (Theorem 1) [node 1]: sigma*c = 800*0.001 = 0.8" in out
    assert "nu = 130" in out and "Theorem 2: a_U =" in out
    assert "certificate: all conditions hold" in out


def test_check_fails_naming_the_node_and_condition(tmp_path, capsys):
    with pytest.warns(RuntimeWarning, match=r"sigma\*c = 1200\*0.001 = 1.2 >= 1: Theorem 1 needs"):
        assert main(["check", write(tmp_path, sigma2=1200.0)]) == 1
    captured = capsys.readouterr()
    assert "FAIL sigma*c < 1 (Theorem 1) [node 1]: sigma*c = 1200*0.001 = 1.2" in captured.out
    assert (
        "etobs: condition failed: node 1: sigma*c < 1 (Theorem 1) (sigma*c = 1200*0.001 = 1.2)"
        in captured.err
    )
    with pytest.warns(RuntimeWarning, match=r"sigma\*c = 1200"):
        assert main(["check", write(tmp_path, sigma2=1200.0), "--json"]) == 1
    data = json.loads(capsys.readouterr().out)
    assert data["ok"] is False and data["nu"] is None
    assert [c["node"] for c in data["conditions"] if not c["holds"]] == [1]


def test_check_rejects_bad_specs(tmp_path, capsys):
    bad = write(tmp_path).replace("check.toml", "check.toml")
    (tmp_path / "check.toml").write_text(SPEC.format(sigma2=800.0).replace("c_v = 0.1", "c_v = 0.1\nfoo = 1"))
    with pytest.raises(SystemExit) as exc:
        main(["check", bad])
    assert exc.value.code == 2
    assert "unknown key `observer.foo`" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["check", str(tmp_path / "missing.toml")])
    assert exc.value.code == 2
    assert "missing.toml' does not exist (SPEC is a TOML file or one of robot_arm)" in capsys.readouterr().err


def test_an_unsolvable_design_is_bad_input_not_a_failed_condition(tmp_path, capsys):
    # x_1 unstable and unseen by y = x_2: the LMIs have no solution -> exit 2, one line
    spec = tmp_path / "lin.toml"
    spec.write_text(
        '[system]\nfactory = "robot_arm"\n[observer]\nA = [[1.0, 0.0], [0.0, -1.0]]\nC = [[0.0, 1.0]]\n'
        'L = "design"\nc_v = 0.1\nc = [0.1, 0.1]\n'
    )
    with pytest.raises(SystemExit) as exc:
        main(["check", str(spec)])
    assert exc.value.code == 2
    assert "etobs: error: the observer LMIs have no solution" in capsys.readouterr().err


@pytest.mark.slow
def test_packaged_robot_arm_check_estimates_E_and_passes(capsys):
    assert main(["check", "robot_arm"]) == 0
    out = capsys.readouterr().out
    assert "certificate: all conditions hold" in out and "ultimate bound on |x - xhat|" in out


def test_check_with_a_designed_gain(tmp_path, capsys):
    path = write(tmp_path).replace("check.toml", "check.toml")
    text = (tmp_path / "check.toml").read_text().replace('L = "paper"', 'L = "design"')
    (tmp_path / "check.toml").write_text(text)
    assert main(["check", path]) == 0
    out = capsys.readouterr().out
    assert "certificate: all conditions hold" in out and "ultimate bound on |x - xhat|" in out


def test_check_refuses_a_problem_the_theorems_do_not_cover(tmp_path, capsys):
    # the robot arm with the observer-copy hold (Remark 3): no certificate, exit 2
    factory = tmp_path / "copy_hold.py"
    factory.write_text(
        "from dataclasses import replace\nimport etobs\nfrom etobs.examples import robot_arm\n\n"
        "@etobs.factory\ndef problem(**kw):\n    return replace(robot_arm(**kw), hold='innovation')\n"
    )
    spec = tmp_path / "check.toml"
    spec.write_text(f'[system]\nfactory = "{factory}:problem"\n[guarantees]\nE = [10.0, 20.0]\n')
    with pytest.raises(SystemExit) as exc:
        main(["check", str(spec)])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "etobs: error: the paper's results (Theorems 1-4) do not cover this problem" in err
    assert "the observer-copy hold" in err and "Traceback" not in err


# --- etobs check and certify agree (issue 15): the chain of tests/design/chain.py ---------------

CHAIN = Path(__file__).parents[1] / "design" / "chain.py"


def _refused(path, capsys, message):
    """``etobs check path`` exits 2 with one line matching ``message``, no traceback."""
    with pytest.raises(SystemExit) as exc:
        main(["check", path])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert re.search(message, err), err
    assert "Traceback" not in err


def _chain_design():
    from etobs.design import certify, observer_gain, propose_rules, quadratic_iss_gains
    from tests.design import chain

    gain = observer_gain(chain.A, chain.C, objective="max_decay", max_gain=5.0)
    iss = quadratic_iss_gains(gain, chain.NODES, c_v=0.1, c=[0.1] * 3)
    rules = propose_rules(iss, sigma=[2.0] * 3, c=[0.05] * 3, a_U=0.5 * iss.a, mu=0.2).rules
    params = {"L": gain.L.tolist(), **chain.rule_params(rules)}
    cert = certify(chain.chain(**params), iss, E=5.0, disturbance=0.02 * 3**0.5)
    return gain, params, cert


def _chain_spec(tmp_path, gain, params, P=None):
    from tests.design import chain

    # Python's repr of a list of floats is TOML; the floats survive the round trip exactly
    table = ", ".join(f"{k} = {v!r}" for k, v in params.items())
    spec = tmp_path / "chain.toml"
    spec.write_text(
        f'[system]\nfactory = "{CHAIN}:chain"\nparams = {{ {table} }}\n'
        f"[observer]\nA = {chain.A.tolist()}\nC = {chain.C.tolist()}\nL = {gain.L.tolist()}\n"
        + ("" if P is None else f"P = {P.tolist()}\n")
        + f"c_v = 0.1\nc = [0.1, 0.1, 0.1]\n[guarantees]\nE = 5.0\ndisturbance = {0.02 * 3**0.5!r}\n"
    )
    return str(spec)


def test_check_with_the_designed_P_gives_certify_s_certificate(tmp_path, capsys):
    gain, params, cert = _chain_design()
    assert main(["check", _chain_spec(tmp_path, gain, params, P=gain.P), "--json"]) == 0
    cli = json.loads(capsys.readouterr().out)
    py = cert.to_dict()
    # the same P, gains and numbers; only the words on where P came from differ
    assert cli["iss"].pop("P_origin") == "given with L (re-checked with eigenvalues)"
    assert py["iss"].pop("P_origin") == "designed together with L by observer_gain (objective 'max_decay')"
    assert cli == py
    assert cli["iss"]["P"] == gain.P.tolist() and cli["error_bound"] == cert.error_bound


def test_check_without_P_says_which_P_it_used(tmp_path, capsys):
    # before: the CLI silently certified with another feasible P for the same L, and its
    # bound differed from certify's with the designed P (2.57 vs 2.15 on the chain)
    gain, params, cert = _chain_design()
    assert main(["check", _chain_spec(tmp_path, gain, params)]) == 0
    out = capsys.readouterr().out
    assert "P found by check_gain for the given L (the trace-1 P with the largest common decrease" in out
    assert "note: no observer.P given: P was found by check_gain for observer.L" in out
    assert "give observer.P (e.g. the ObserverGain.P of the design that gave L)" in out
    bound = float(out.split("ultimate bound on |x - xhat|: ")[1].split()[0])
    assert bound != pytest.approx(cert.error_bound, rel=1e-2)  # another P, another bound: both valid


@pytest.mark.parametrize(
    "change, message",
    [
        (
            "P_design",
            r"`observer.P` goes with a given `observer.L` \(a matrix or 'paper'\); with L = 'design'",
        ),
        (
            "P_small",
            r"`observer.L` with `observer.P` fails the LMI re-check: the given P does not fit L and Q",
        ),
        ("P_shape", r"error: [^`]*`observer.P` has shape \(2, 2\); expected \(6, 6\)"),
        ("P_asym", r"error: [^`]*`observer.P` must be symmetric; got P - P' with largest entry 1"),
        ("P_text", r"error: [^`]*`observer.P` must be a matrix of real numbers; got 'designed'"),
    ],
)
def test_check_refuses_a_bad_P(tmp_path, capsys, change, message):
    gain, params, _ = _chain_design()
    P = {"P_small": 0.01 * np.eye(6), "P_shape": np.eye(2), "P_asym": np.triu(np.ones((6, 6)))}.get(
        change, gain.P
    )
    path = _chain_spec(tmp_path, gain, params, P=P)
    text = Path(path).read_text()
    if change == "P_design":
        text = text.replace(f"\nL = {gain.L.tolist()}", '\nL = "design"')
    if change == "P_text":
        text = text.replace(f"P = {gain.P.tolist()}", 'P = "designed"')
    Path(path).write_text(text)
    _refused(path, capsys, message)


# --- what `disturbance` bounds (issue 15): the wind chain of tests/design/wind_chain.py ------------

WIND = Path(__file__).parents[1] / "design" / "wind_chain.py"


def _wind_spec(tmp_path, observer="", guarantees="", e_scale=30.0):
    """A spec of the wind chain (v entering as e_scale e_4) with the designed L and P."""
    from etobs.design import observer_gain, propose_rules, quadratic_iss_gains
    from tests.design import chain, wind_chain

    gain = observer_gain(wind_chain.A, wind_chain.C, objective="max_decay", max_gain=5.0)
    iss = quadratic_iss_gains(gain, wind_chain.NODES, c_v=0.1, c=[0.1, 0.1])
    rules = propose_rules(iss, sigma=[2.0, 2.0], c=[0.05, 0.05], nu=0.05).rules
    params = {
        "L": gain.L.tolist(),
        **chain.rule_params(rules),
        "e_scale": e_scale,
        "const": True,
        "wind": 0.05,
    }
    table = ", ".join(
        f"{k} = {str(v).lower() if isinstance(v, bool) else repr(v)}" for k, v in params.items()
    )
    spec = tmp_path / "wind.toml"
    spec.write_text(
        f'[system]\nfactory = "{WIND}:mychain"\nparams = {{ {table} }}\n'
        f"[observer]\nA = {wind_chain.A.tolist()}\nC = {wind_chain.C.tolist()}\nL = {gain.L.tolist()}\n"
        f"P = {gain.P.tolist()}\nc_v = 0.1\nc = [0.1, 0.1]\n{observer}[guarantees]\nE = 5.0\n{guarantees}"
    )
    return str(spec), gain, params


def test_check_takes_the_plant_s_disturbance_matrix_and_says_so(tmp_path, capsys):
    from etobs.design import certify, check_gain, quadratic_iss_gains
    from tests.design import wind_chain

    path, gain, params = _wind_spec(tmp_path, guarantees="disturbance = 0.05\n")
    assert main(["check", path, "--json"]) == 0
    cli = json.loads(capsys.readouterr().out)
    assert cli["iss"]["E_v"] == [[0.0], [0.0], [0.0], [30.0]] and cli["disturbance"] == 0.05
    assert cli["notes"] == [
        "no observer.E_v given: theta is for the plant's disturbance input E_v = [[0.0], [0.0], [0.0], [30.0]], "
        "read from f_p (x' = ... + E_v v), not for quadratic_iss_gains' default, the identity"
    ]
    # the same bound as certify with the plant's E_v (before: the identity's, 30 times too small)
    again = check_gain(wind_chain.A, wind_chain.C, gain.L, P=gain.P)
    iss = quadratic_iss_gains(
        again, wind_chain.NODES, c_v=0.1, c=[0.1, 0.1], E_v=wind_chain.disturbance_matrix(30.0)
    )
    py = certify(wind_chain.mychain(**params), iss, E=5.0, disturbance=0.05)
    assert cli["error_bound"] == py.error_bound
    # given as observer.E_v: the same certificate, without the note
    path, _, _ = _wind_spec(tmp_path, observer="E_v = [[0.0], [0.0], [0.0], [30.0]]\n")
    assert main(["check", path]) == 0
    out = capsys.readouterr().out
    assert f"ultimate bound on |x - xhat|: {py.error_bound:.6g} for |v| <= 0.05\n" in out
    assert (
        "note: disturbance not given: the error bound is for |v| <= sup_t |v(t)| = 0.05, of problem.v" in out
    )
    assert "no observer.E_v given" not in out


@pytest.mark.parametrize(
    ("observer", "guarantees", "message"),
    [
        (
            "E_v = [[0.0], [0.0], [0.0], [1.0]]\n",
            "",
            r"error: `iss` was computed for a disturbance entering as x' = \.\.\. \+ E_v v with E_v shape \(4, 1\) "
            r"\[\[0\.0\], \[0\.0\], \[0\.0\], \[1\.0\]\]; the plant 'linear plant' has E_v = \[\[0\.0\], \[0\.0\], "
            r"\[0\.0\], \[30\.0\]\] .*\(`observer\.E_v` in an `etobs check` spec\)",
        ),
        ("E_v = [[0.0], [1.0]]\n", "", r"error: [^`]*`observer\.E_v` has shape \(2, 1\); expected \(4, 1\)"),
        (
            "",
            "disturbance = 0.01\n",
            r"error: [^`]*`guarantees\.disturbance` = 0\.01 is below sup_t \|v\(t\)\| = 0\.05 of the problem's v "
            r"\(Constant\)",
        ),
    ],
)
def test_check_refuses_a_disturbance_it_cannot_certify(tmp_path, capsys, observer, guarantees, message):
    path, _, _ = _wind_spec(tmp_path, observer=observer, guarantees=guarantees)
    _refused(path, capsys, message)


def test_check_refuses_a_U_and_disturbance_without_an_observer(tmp_path, capsys):
    # the new user's c7.toml: before, exit 0 and "all conditions hold", the two keys unused
    spec = tmp_path / "c7.toml"
    spec.write_text(
        SPEC.format(sigma2=800.0).split("[observer]")[0] + "[guarantees]\na_U = 0.18\ndisturbance = 0.01\n"
    )
    with pytest.raises(SystemExit) as exc:
        main(["check", str(spec)])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert (
        "c7.toml: `guarantees.a_U` needs an `[observer]` table: a_U and disturbance serve only Theorem 2"
        in err
    )
    assert "add `[observer]` or remove `guarantees.a_U` and `guarantees.disturbance`" in err


def test_check_fails_when_the_system_s_L_is_not_the_observer_s(tmp_path, capsys):
    # before: exit 0, the ISS gains of observer.L certified for a problem run with another L
    other = "params = { L = [[0.0, 0.0], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]], sigma = [600.0, 800.0], "
    text = SPEC.format(sigma2=800.0).replace("params = { sigma = [600.0, 800.0], ", other)
    (tmp_path / "check.toml").write_text(text)
    assert main(["check", str(tmp_path / "check.toml")]) == 1
    err = capsys.readouterr().err
    assert "etobs: condition failed: ISS gains are the problem's observer and plant (Assumption 2)" in err
    assert "the observer's response to ybar is not the L of the ISS gains" in err


@pytest.mark.parametrize("runs", ["1e7", "1e8", "10000000", "100000000"])
def test_check_refuses_an_E_estimate_above_the_limit_before_any_run(tmp_path, capsys, runs):
    # before: 1e7 ran for minutes without a word, 1e8 ended in a MemoryError traceback
    extra = f"E_estimate = {{ low = [0, 0, 0, 0], high = [20, 10, 20, 10], runs = {runs} }}\n"
    text = SPEC.format(sigma2=800.0).replace("E = [10.0, 20.0]\n", extra)
    (tmp_path / "check.toml").write_text(text)
    if "e" in runs:  # TOML floats: refused as not an integer, before any run
        _refused(str(tmp_path / "check.toml"), capsys, r"`guarantees.E_estimate.runs` must be an integer")
        return
    _refused(
        str(tmp_path / "check.toml"),
        capsys,
        rf"^etobs: error: \S+: `guarantees.E_estimate.runs` = {runs} \(plus 16 corners\) over t_end = 30 "
        r"asks for [0-9.e+]+ grid points [^\n]*; the limit is 5e\+06: lower runs or t_end\n$",
    )


@pytest.mark.slow
def test_packaged_robot_arm_names_E_as_an_estimate_from_the_box_and_its_corners(capsys):
    assert main(["check", "robot_arm"]) == 0
    out = capsys.readouterr().out
    assert (
        "assumed (not checked): E = (" in out
        and ") is an estimate, not a bound: the largest |dy_i/dt|" in out
    )
    assert "and its 16 corners" in out and "stays below E_i" in out
