import json

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
