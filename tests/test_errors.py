"""Every input check names the argument, the expectation and what it received."""

import math

import numpy as np
import pytest

from etobs import (
    Custom,
    EstimationProblem,
    InputError,
    InputTypeError,
    Linear,
    Node,
    Observer,
    Plant,
    Power,
    SaveAt,
    SolverOptions,
    StaticRule,
    Status,
    luenberger,
    simulate,
)
from etobs import _validate as v
from etobs.estimation import transmission_counts
from etobs.examples import robot_arm
from etobs.hybrid import HybridSystem, solve, solve_reference, status_message


@pytest.mark.parametrize(
    ("call", "exc", "match"),
    [
        (lambda: v.integer("n", 1.5), InputTypeError, r"`n` must be an integer; got 1.5 \(float\)"),
        (lambda: v.integer("n", True), InputTypeError, r"`n` must be an integer; got True \(bool\)"),
        (lambda: v.vector("a", "xy"), InputTypeError, r"`a` must be a vector of real numbers; got 'xy'"),
        (
            lambda: v.vector("a", [[1, 2]]),
            InputError,
            r"`a` must be a vector \(1-D\); got an array of shape \(1, 2\)",
        ),
        (lambda: v.vector("a", [1, 2], 3), InputError, r"`a` must have 3 entries; got 2 \(shape \(2,\)\)"),
        (lambda: v.vector("a", [1, np.inf]), InputError, r"`a` must be finite; got \[1.0, inf\]"),
        (lambda: v.matrix("L", "x", (2, 2)), InputTypeError, r"`L` must be a matrix of real numbers"),
        (
            lambda: v.matrix("L", np.ones((3, 2)), (4, 2)),
            InputError,
            r"`L` has shape \(3, 2\); expected \(4, 2\)",
        ),
        (lambda: v.matrix("L", [[np.nan]], (1, 1)), InputError, r"`L` must be finite"),
        (lambda: v.batch("x0", "ab", 2), InputTypeError, r"`x0` must be an array of real numbers"),
        (lambda: v.batch("x0", np.ones((0, 2)), 2), InputError, r"`x0` has shape \(0, 2\); expected \(2,\)"),
        (lambda: v.function("f_p", 3), InputTypeError, r"`f_p` must be callable; got 3 \(int\)"),
        (
            lambda: v.index_tuple("outputs", 0.5),
            InputTypeError,
            r"`outputs` must be an int or a sequence of ints",
        ),
        (lambda: v.real("x", 2.0, upper=1.0, upper_open=True), InputError, r"`x` must be < 1; got 2"),
        # integers beyond float range (from a spec) raised OverflowError; long values are shortened
        (
            lambda: v.real("x", 10**400),
            InputError,
            r"`x` must be a finite real number; got 1000000000\.\.\.0+$",
        ),
        (
            lambda: v.vector("a", [10**400]),
            InputTypeError,
            r"`a` must be a vector of real numbers; got \[10+\.\.\.",
        ),
        (lambda: v.matrix("L", [[10**400]], (1, 1)), InputTypeError, r"`L` must be a matrix of real numbers"),
        (lambda: v.batch("x0", [10**400], 1), InputTypeError, r"`x0` must be an array of real numbers"),
        (
            lambda: v.vector("a", ["x"] * 10**5),
            InputTypeError,
            r"got \['x', 'x', 'x', 'x', 'x', 'x', 'x', 'x', \.\.\.\]$",
        ),
    ],
)
def test_validators(call, exc, match):
    with pytest.raises(exc, match=match):
        call()


def _plant():
    return Plant(f_p=lambda t, x, u, v: -x, h=lambda x: x, n_x=1, n_y=1)


def _node():
    return Node((0,), StaticRule(gamma=Linear(1.0), eps=1.0))


@pytest.mark.parametrize(
    ("call", "exc", "match"),
    [
        (
            lambda: EstimationProblem(_plant(), "obs", [_node()]),
            InputTypeError,
            r"`observer` must be an Observer; got str",
        ),
        (
            lambda: Observer(f_o=lambda *a: a[1], n_z=1, psi="first"),
            InputTypeError,
            r"`psi` must be callable; got 'first'",
        ),
        (
            lambda: simulate("robot arm", [0.0], 1.0),
            InputError,
            r"`problem` must be an EstimationProblem; got str",
        ),
        (lambda: robot_arm(L=np.ones((2, 4))), InputError, r"`L` has shape \(2, 4\); expected \(4, 2\)"),
        (lambda: robot_arm(sigma=(1, 2, 3)), InputError, r"`sigma` must have 2 entries; got 3"),
        (lambda: SolverOptions(first_step=0.0), InputError, r"`first_step` must be > 0; got 0"),
        (
            lambda: Plant(lambda t, x, u, v, p: x, lambda x, p: x, n_x=1, n_y=1, params=[np.nan]),
            InputError,
            r"`params` must be finite; got \[nan\]",
        ),
        (
            lambda: HybridSystem(
                1, 0, lambda t, x, p: x, lambda t, x, p: x, lambda k, t, x, p: x, params=[[1.0]]
            ),
            InputError,
            r"`params` must be a vector \(1-D\); got an array of shape \(1, 1\)",
        ),
        (
            lambda: solve(
                HybridSystem(1, 0, lambda t, x: x, lambda t, x: x, lambda k, t, x: x),
                [0.0],
                (0, 1),
                backend="jax",
            ),
            InputError,
            r"`backend` must be one of \('auto', 'engine', 'scipy'\) \(or 'numba' for 'engine'\); got 'jax'",
        ),
        (lambda: solve("system", [0.0], (0, 1)), InputTypeError, r"`system` must be a HybridSystem; got str"),
        (
            lambda: solve(
                HybridSystem(1, 0, lambda t, x: x, lambda t, x: x, lambda k, t, x: x),
                [0.0],
                (0, 1),
                save=[0.5, 1.0],
            ),
            InputTypeError,
            r"`save` must be a SaveAt or None; the states on a time grid are save=SaveAt\(grid=times\); "
            r"got list \[0.5, 1.0\]",
        ),
        (
            lambda: solve(
                HybridSystem(1, 0, lambda t, x: x, lambda t, x: x, lambda k, t, x: x),
                [0.0],
                (0, 1),
                backend="scipy",
                options={"max_jumps": 3},
            ),
            InputTypeError,
            r"`options` must be a SolverOptions.*got dict \{'max_jumps': 3\} \(a dict of settings is "
            r"SolverOptions\(\*\*settings\)\)",
        ),
        (
            lambda: solve_reference("system", [0.0], (0, 1)),
            InputTypeError,
            r"`system` must be a HybridSystem; got str",
        ),
        (
            lambda: HybridSystem(1, 2, lambda t, x: x, lambda t, x: x, lambda k, t, x: x, rule_names=("a",)),
            InputError,
            r"`rule_names` has 1 names; expected n_rules=2",
        ),
        (
            lambda: Custom(lambda s: np.array([s, s])),
            InputError,
            r"`fn` must map a float s >= 0 to a float \(written for one value, not an array\); "
            r"at s in \[0.0, .*\] it raised TypeError",
        ),
        (
            lambda: Custom(lambda s: s if s < 100.0 else math.inf),
            InputError,
            r"`fn` must give finite values; at s=\[0.0, 0.001, 0.1, 1.0, 10.0, 1000.0\] it gives "
            r"\[0.0, 0.001, 0.1, 1.0, 10.0, inf\]",
        ),
        (
            lambda: transmission_counts(simulate(robot_arm(), [3, 2, 3, -2], 0.1), window=5.0),
            InputError,
            r"`window` must be a pair \(t_start, t_stop\); got 5.0",
        ),
        (
            lambda: simulate(robot_arm(), [3, 2, 3, -2], 0.1).arc(3),
            InputError,
            r"`run` must be in 0..0; got 3",
        ),
    ],
)
def test_object_errors(call, exc, match):
    with pytest.raises(exc, match=match):
        call()


def test_plot_run_out_of_range():
    from etobs.plot import plot_error

    with pytest.raises(InputError, match=r"`run` must be in 0..0; got 1"):
        plot_error(simulate(robot_arm(), [3, 2, 3, -2], 0.1), run=1)


def test_luenberger_and_custom_psi():
    # x' = -x from x(0) = 1, observed by xhat' = -xhat + 2 (ybar - xhat). With |e| < 1 = eps
    # the node never transmits, so ybar = 1 and xhat(t) = 2/3 (1 - exp(-3 t)).
    obs = luenberger(lambda t, x, u: -x, L=[[2.0]])
    pb = EstimationProblem(_plant(), obs, [_node()])
    res = simulate(pb, [1.0], 3.0, save=SaveAt(grid=[3.0]))
    assert len(res.transmissions) == 0
    assert res.on_grid().xhat[0, 0, 0] == pytest.approx(2 / 3 * (1 - np.exp(-9.0)), rel=1e-9)
    # z = (unused, xhat): z1' = ybar - z1, z0' = 0, psi(z) = z1
    wide = Observer(
        f_o=lambda t, z, u, ybar, yhat: np.concatenate((0.0 * z[:1], ybar - z[1:])),
        n_z=2,
        psi=lambda z: z[1:],
    )
    res = simulate(EstimationProblem(_plant(), wide, [_node()]), [1.0], 0.5, save=SaveAt(grid=[0.5]))
    assert res.arc(0).xhat.shape[-1] == 1
    # ybar = 1 (no transmission), so xhat(t) = 1 - exp(-t)
    assert res.on_grid().xhat[0, 0, 0] == pytest.approx(1 - np.exp(-0.5), rel=1e-9)


def test_power_and_custom_with_inverse():
    f = Custom(lambda s: 2 * s, inv=lambda r: r / 2, name="two s")
    assert str(f) == "two s" and float(f.inverse(np.array(4.0))) == 2.0
    assert str(Power(2, 3)) == "2*s^3" and str(Linear(2)) == "2*s"


def test_status_labels_and_messages():
    assert Status.MAX_JUMPS.label == "max_jumps" and not Status.MAX_JUMPS.ok and Status.COMPLETED.ok
    # every status has a sentence on both solvers; the reference's model_error does not send
    # the user to the reference
    for s in Status:
        assert status_message(s) and status_message(s, backend="scipy")
    assert "backend='scipy'" in status_message(Status.MODEL_ERROR, backend="engine")
    assert "backend='scipy'" not in status_message(Status.MODEL_ERROR, backend="scipy")
    res = simulate(robot_arm(), [[3, 2, 3, -2]] * 2, 0.5, options=SolverOptions(max_steps=3))
    assert res.status_labels() == ["max_steps", "max_steps"]
    assert not res.ok
    assert res.transmissions.counts(2, 2).sum() == 0


@pytest.mark.parametrize("debug", ["", "1"])
def test_the_cli_prints_one_line_and_the_chain_only_under_etobs_debug(monkeypatch, capsys, debug):
    import argparse

    from etobs.cli import main as cli
    from etobs.errors import ModelError

    def fails(args):
        try:
            raise ValueError("numba's reason, deep inside")
        except ValueError as exc:
            raise ModelError("`f_p` cannot be compiled: numba's reason") from exc

    parser = cli.build_parser()
    monkeypatch.setattr(parser, "parse_args", lambda argv: argparse.Namespace(func=fails))
    monkeypatch.setattr(cli, "build_parser", lambda: parser)
    monkeypatch.setenv("ETOBS_DEBUG", debug)
    with pytest.raises(SystemExit) as info:
        cli.main(["check", "x.toml"])
    err = capsys.readouterr().err
    assert info.value.code == 2
    assert err.splitlines()[-1] == "etobs: error: `f_p` cannot be compiled: numba's reason"
    assert ("numba's reason, deep inside" in err) == bool(debug)
    assert len(err.splitlines()) == 1 or debug
