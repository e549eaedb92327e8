"""``etobs check SPEC --cost``: what the spec's model costs on the engine (issue 23)."""

from etobs.cli.main import main


def test_check_cost_prints_the_cost_report_of_the_packaged_robot_arm(capsys):
    assert main(["check", "robot_arm", "--cost"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "ModelCost of 'robot arm' on the engine (time per call, slowest first):"
    assert sorted(line.split()[0] for line in out[1:4]) == ["f_o", "f_p", "h"]
    assert out[4].startswith("  one solver step: ")
    assert "certificate" not in "\n".join(out).lower()  # the model alone: no certificate
