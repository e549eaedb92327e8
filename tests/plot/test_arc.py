"""plot_hybrid_arc draws the arc's own points: flows solid, one dashed segment per jump."""

import numpy as np
import pytest

from etobs import InputError, InputTypeError, SaveAt, simulate
from etobs.hybrid import HybridArc, solve
from etobs.plot import plot_hybrid_arc
from tests.hybrid.systems import bouncing_ball
from tests.plot.models import X0, two_sensors


def _finite(a):
    a = np.asarray(a, dtype=float)
    return a[np.isfinite(a)]


def _flows(ax):
    return [ln for ln in ax.get_lines() if ln.get_linestyle() == "-"]


def _jumps(ax):
    (coll,) = ax.collections
    return np.asarray(coll.get_segments()), coll


def test_flows_are_the_arcs_points_cut_at_every_jump(arcs_only):
    arc = arcs_only.arc(1)
    fig, (ax, _) = plot_hybrid_arc(arcs_only, run=1, what="x")
    lines = _flows(ax)
    assert len(lines) == 2  # one per state
    n_jumps = len(arcs_only.transmissions.select(run=1))
    assert n_jumps > 10
    for k, line in enumerate(lines):
        np.testing.assert_array_equal(_finite(line.get_xdata()), arc.t)
        np.testing.assert_array_equal(_finite(line.get_ydata()), arc.x[:, k])
        # a NaN between flow intervals, at each jump time: no flow line crosses a jump
        t = np.asarray(line.get_xdata(), dtype=float)
        cut = np.flatnonzero(np.isnan(t))
        assert cut.size == n_jumps
        np.testing.assert_array_equal(t[cut - 1], arcs_only.transmissions.select(run=1).t)
        np.testing.assert_array_equal(t[cut + 1], t[cut - 1])
    assert f"{n_jumps} jumps" in fig._suptitle.get_text()


def test_one_dashed_segment_per_jump_from_the_value_before_to_the_value_after(arcs_only):
    arc = arcs_only.arc(0)
    log = arcs_only.transmissions.select(run=0)
    _, (ax, _) = plot_hybrid_arc(arcs_only, run=0, what="e", components=[0])
    seg, coll = _jumps(ax)
    assert len(seg) == len(log)
    ((_, dashes),) = coll.get_linestyle()
    assert dashes is not None  # dashed, not solid
    np.testing.assert_array_equal(seg[:, 0, 0], log.t)  # at the jump times
    np.testing.assert_array_equal(seg[:, 1, 0], log.t)  # vertical
    before = np.searchsorted(arc.j, log.j, side="right") - 1
    np.testing.assert_array_equal(seg[:, 0, 1], arc.e[before, 0])
    np.testing.assert_array_equal(seg[:, 1, 1], arc.e[before + 1, 0])
    # node 0's own transmissions reset its e_1 to 0 (eq. (4): ybar_1 = ytilde_1 then)
    own = log.rule == 0
    assert own.any() and (~own).any()
    np.testing.assert_array_equal(seg[own, 1, 1], 0.0)
    assert np.all(np.abs(seg[own, 0, 1]) > 0)


def test_the_bottom_panel_is_the_hybrid_time_domain(arcs_only):
    arc = arcs_only.arc(0)
    _, (_, ax_j) = plot_hybrid_arc(arcs_only)
    (line,) = _flows(ax_j)
    np.testing.assert_array_equal(_finite(line.get_xdata()), arc.t)
    np.testing.assert_array_equal(_finite(line.get_ydata()), arc.j)
    seg, _ = _jumps(ax_j)
    log = arcs_only.transmissions.select(run=0)
    np.testing.assert_array_equal(seg[:, 0, 1], log.j)
    np.testing.assert_array_equal(seg[:, 1, 1], log.j + 1)
    assert ax_j.get_ylabel() == "j"


def test_default_is_the_estimation_error_on_a_log_axis(arcs_only):
    arc = arcs_only.arc(0)
    _, (ax, _) = plot_hybrid_arc(arcs_only)
    (line,) = _flows(ax)
    np.testing.assert_array_equal(_finite(line.get_ydata()), np.linalg.norm(arc.x - arc.xhat, axis=1))
    assert ax.get_yscale() == "log"
    _, (ax, _) = plot_hybrid_arc(arcs_only, log=False)
    assert ax.get_yscale() == "linear"
    _, (ax, _) = plot_hybrid_arc(arcs_only, what="x", log=True)
    assert ax.get_yscale() == "log"


@pytest.mark.parametrize("what", ["x", "xhat", "z", "ybar", "e", "eta"])
def test_each_variable_is_the_arcs(arcs_only, what):
    arc = arcs_only.arc(0)
    _, (ax, _) = plot_hybrid_arc(arcs_only, what=what)
    values = getattr(arc, what)
    lines = _flows(ax)
    assert len(lines) == values.shape[1]
    for k, line in enumerate(lines):
        np.testing.assert_array_equal(_finite(line.get_ydata()), values[:, k])
    assert len(ax.collections) == len(lines)  # one collection of dashed jumps per curve
    for coll in ax.collections:
        assert len(coll.get_segments()) == len(arcs_only.transmissions.select(run=0))


def test_eta_names_the_nodes(arcs_only):
    arc = arcs_only.arc(0)
    _, (ax, _) = plot_hybrid_arc(arcs_only, what="eta", components=1)
    (line,) = _flows(ax)
    np.testing.assert_array_equal(_finite(line.get_ydata()), arc.eta[:, 1])
    assert "sensor 2" in line.get_label()


def test_a_kept_grid_refines_the_flows_and_moves_no_jump(arcs_and_grid):
    arc = arcs_and_grid.arc(0)
    grid = arcs_and_grid.on_grid()
    fig, (ax, _) = plot_hybrid_arc(arcs_and_grid, what="x", components=[0])
    (line,) = _flows(ax)
    t = _finite(line.get_xdata())
    assert t.size == arc.t.size + grid.t.shape[1]
    assert np.all(np.diff(t) >= 0)
    np.testing.assert_array_equal(np.sort(t), np.sort(np.concatenate([arc.t, grid.t[0]])))
    seg, _ = _jumps(ax)
    log = arcs_and_grid.transmissions.select(run=0)
    np.testing.assert_array_equal(seg[:, 0, 0], log.t)
    # after a jump the value is the arc's (the grid keeps the value before a jump)
    np.testing.assert_array_equal(seg[:, 1, 1], arc.x[np.searchsorted(arc.j, log.j + 1), 0])
    assert "refined with the save grid" in fig._suptitle.get_text()


@pytest.fixture(scope="module")
def ball():
    # dropped from 1 m, the ball's impacts accumulate at t = 3 sqrt(2 / g) = 1.35 s (Zeno)
    save = SaveAt(grid=np.linspace(0.0, 1.3, 61))
    return solve(bouncing_ball(restitution=0.5), x0=[1.0, 0.0], t_span=(0.0, 1.3), save=save, backend="scipy")


def test_a_hybrid_solution_and_a_hybrid_arc(ball):
    arc = ball.arcs[0]
    n_impacts = len(ball.jumps)
    assert n_impacts >= 5
    fig, (ax, _) = plot_hybrid_arc(HybridArc(arc.t, arc.j, arc.x), components=[1])
    seg, _ = _jumps(ax)
    assert len(seg) == n_impacts
    # each impact reverses the velocity and halves it: the dashed segment joins v and -v/2
    np.testing.assert_allclose(seg[:, 1, 1], -0.5 * seg[:, 0, 1], rtol=1e-12)
    assert np.all(seg[:, 0, 1] < 0)
    assert "refined" not in fig._suptitle.get_text()
    fig, (ax, _) = plot_hybrid_arc(ball, components=[1])  # the solution: arc and grid
    assert len(_jumps(ax)[0]) == n_impacts
    assert _finite(_flows(ax)[0].get_xdata()).size == len(arc) + 61
    assert "refined" in fig._suptitle.get_text()


def test_renders(arcs_and_grid, ball, tmp_path):
    for i, (fig, _) in enumerate([plot_hybrid_arc(arcs_and_grid, what="e"), plot_hybrid_arc(ball)]):
        fig.savefig(tmp_path / f"arc{i}.png")
        assert (tmp_path / f"arc{i}.png").stat().st_size > 10_000


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"run": 2}, InputError, r"`run` must be in 0\.\.1; got 2"),
        ({"run": -1}, InputError, r"`run` must be in 0\.\.1; got -1"),
        (
            {"run": "0"},
            InputTypeError,
            r"`run` must be an integer or a sequence of integers; got '0' \(str\)",
        ),
        ({"run": True}, InputTypeError, r"`run` must be an integer"),
        ({"what": "xi"}, InputError, r"`what` must be one of \['e', 'error', 'eta', .*\]; got 'xi'"),
        ({"what": 3}, InputTypeError, r"`what` must be a string; got 3 \(int\)"),
        ({"what": "x", "components": 2}, InputError, r"`components` must be in 0\.\.1; got 2"),
        ({"what": "x", "components": []}, InputError, r"`components` must name at least one component"),
        ({"what": "x", "components": [0, 0]}, InputError, r"`components` must not repeat an index"),
        ({"components": 0}, InputError, r"`components` selects entries of a vector; `what='error'` is"),
        ({"log": "yes"}, InputTypeError, r"`log` must be true or false; got 'yes'"),
    ],
)
def test_bad_arguments_are_named(arcs_only, kwargs, error, match):
    with pytest.raises(error, match=match):
        plot_hybrid_arc(arcs_only, **kwargs)


def test_a_result_without_arcs_says_how_to_keep_them(grid_only):
    with pytest.raises(InputError, match=r"kept no arcs: simulate with save=SaveAt\(steps=True\)"):
        plot_hybrid_arc(grid_only)


def test_bad_hybrid_inputs_are_named(ball):
    arc = ball.arcs[0]
    with pytest.raises(InputError, match=r"`what` must be 'x' for a HybridArc .*; got 'error'"):
        plot_hybrid_arc(arc, what="error")
    with pytest.raises(InputError, match=r"`run` must be 0 for a HybridArc \(one run\); got 1"):
        plot_hybrid_arc(arc, run=1)
    with pytest.raises(InputError, match=r"`run` must be in 0\.\.0; got 1"):
        plot_hybrid_arc(ball, run=1)
    no_arcs = solve(
        bouncing_ball(), x0=[1.0, 0.0], t_span=(0.0, 1.0), save=SaveAt(steps=False), backend="scipy"
    )
    with pytest.raises(InputError, match=r"this solution kept no arcs: solve with save=SaveAt\(steps=True\)"):
        plot_hybrid_arc(no_arcs)
    with pytest.raises(
        InputTypeError, match=r"`result` must be an EstimationResult, a HybridSolution or a Hybrid"
    ):
        plot_hybrid_arc({"t": arc.t})


def test_eta_of_a_stateless_rule_is_refused():
    from etobs import StaticRule

    pb = two_sensors()
    nodes = [pb.nodes[0], type(pb.nodes[1])((1,), StaticRule(gamma=pb.nodes[1].rule.gamma, eps=0.01))]
    pb = type(pb)(pb.plant, pb.observer, nodes=nodes, v=pb.v)
    result = simulate(pb, x0=X0[0], t_end=1.0, backend="scipy")
    with pytest.raises(InputError, match=r"`components` names node 1 \(node1\), whose rule has no state eta"):
        plot_hybrid_arc(result, what="eta", components=[1])
    _, (ax, _) = plot_hybrid_arc(result, what="eta")  # the default: the nodes that have one
    assert len(_flows(ax)) == 1
