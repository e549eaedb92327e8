"""plot_held_outputs: the held values as exact steps, jumping to the values sent at the transmissions."""

import numpy as np
import pytest

from etobs import (
    EstimationProblem,
    InputError,
    InputNode,
    InputTypeError,
    Link,
    Network,
    Node,
    Plant,
    SaveAt,
    Sinusoid,
    luenberger,
    simulate,
)
from etobs.plot import plot_held_outputs, plot_inter_event_times
from tests.plot.models import T_END, X0, A, rule, two_sensors


def _line(ax, label):
    (line,) = [ln for ln in ax.get_lines() if ln.get_label() == label]
    return np.asarray(line.get_xdata(), dtype=float), np.asarray(line.get_ydata(), dtype=float), line


def _ticks(ax):
    (line,) = [ln for ln in ax.get_lines() if ln.get_label().startswith("transmissions")]
    return np.asarray(line.get_xdata(), dtype=float)


def _jump_rows(arc, log):
    """Index of the row just before each jump of ``log`` in the arc (the one after is + 1)."""
    before = np.searchsorted(arc.j, log.j, side="right") - 1
    np.testing.assert_array_equal(arc.t[before], log.t)
    np.testing.assert_array_equal(arc.j[before + 1], log.j + 1)
    return before


@pytest.mark.parametrize("run", [0, 1])
def test_steps_jump_to_the_values_sent_at_the_transmissions_and_only_there(arcs_only, run):
    arc = arcs_only.arc(run)
    _, axes = plot_held_outputs(arcs_only, run=run)
    assert len(axes) == 2
    assert "from the hybrid arc: exact steps" in axes[0].get_title()
    for i, ax in enumerate(axes):
        log = arcs_only.transmissions.select(run=run, rule=i)
        assert len(log) > 10
        t, held, _ = _line(ax, rf"$\bar y_{{{i + 1}}}$")
        np.testing.assert_array_equal(t, arc.t)
        np.testing.assert_array_equal(held, arc.ybar[:, i])
        t, measured, _ = _line(ax, f"$y_{{{i + 1}}}$")
        np.testing.assert_allclose(measured, arc.x[:, i], rtol=0, atol=1e-13)  # h(x) = x, no noise
        before = _jump_rows(arc, log)
        # what node i sent: its output at the transmission, y_i = x_i
        t_sent, sent, _ = _line(ax, "values sent")
        np.testing.assert_array_equal(t_sent, log.t)
        np.testing.assert_allclose(sent, arc.x[before, i], rtol=0, atol=1e-13)
        # the steps jump to those values at those instants, and change nowhere else
        np.testing.assert_allclose(held[before + 1], sent, rtol=0, atol=1e-13)
        np.testing.assert_array_equal(np.flatnonzero(np.diff(held) != 0), before)
        np.testing.assert_array_equal(_ticks(ax), arcs_only.transmission_times(run, i))
        assert ax.get_ylabel() == f"sensor {i + 1}"


def test_from_the_grid_the_steps_come_exact_from_the_transmission_log(grid_only, arcs_only):
    grid = grid_only.on_grid()
    _, axes = plot_held_outputs(grid_only, run=1)
    assert "steps from the transmission log (exact)" in axes[0].get_title()
    arc = arcs_only.arc(1)  # the same runs, solved keeping the arcs
    for i, ax in enumerate(axes):
        log = grid_only.transmissions.select(run=1, rule=i)
        truth = arcs_only.transmissions.select(run=1, rule=i)
        np.testing.assert_allclose(log.t, truth.t, rtol=0, atol=1e-12)
        t, held, line = _line(ax, rf"$\bar y_{{{i + 1}}}$")
        assert line.get_drawstyle() == "steps-post"
        # a step at each transmission instant, to the value the arc holds after it
        np.testing.assert_array_equal(t, np.concatenate([[0.0], log.t, [T_END]]))
        after = arc.ybar[_jump_rows(arc, truth) + 1, i]
        np.testing.assert_allclose(held[1:-1], after, rtol=0, atol=1e-12)
        assert held[0] == grid.ybar[1][0, i] and held[-1] == held[-2]
        # and at every grid point, the step's value is the grid's (the grid keeps the
        # value before a jump at a jump time, hence side="left")
        k = np.searchsorted(t, grid.t[1], side="left") - 1
        np.testing.assert_array_equal(held[np.maximum(k, 0)], grid.ybar[1][:, i])
        t_sent, sent, _ = _line(ax, "values sent")
        np.testing.assert_array_equal(t_sent, log.t)
        np.testing.assert_array_equal(sent, held[1:-1])
        np.testing.assert_array_equal(_ticks(ax), log.t)


def test_from_the_grid_with_a_network_the_held_values_are_the_grids():
    pb = two_sensors(network=Network(Link(delay=0.1)))
    save = SaveAt(steps=False, grid=np.linspace(0.0, 2.0, 81))
    result = simulate(pb, x0=X0[0], t_end=2.0, save=save, backend="scipy")
    grid = result.on_grid()
    _, axes = plot_held_outputs(result)
    assert "from the save grid: held values at its points" in axes[0].get_title()
    t, held, line = _line(axes[0], r"$\bar y_{1}$")
    assert line.get_drawstyle() == "steps-post"
    np.testing.assert_array_equal(t, grid.t[0])
    np.testing.assert_array_equal(held, grid.ybar[0][:, 0])


def test_with_arcs_and_grid_the_grid_points_join_the_arcs(arcs_and_grid):
    arc, grid = arcs_and_grid.arc(0), arcs_and_grid.on_grid()
    _, axes = plot_held_outputs(arcs_and_grid)
    t, held, line = _line(axes[0], r"$\bar y_{1}$")
    assert line.get_drawstyle() == "default"
    assert t.size == arc.t.size + grid.t.shape[1] and np.all(np.diff(t) >= 0)
    log = arcs_and_grid.transmissions.select(run=0, rule=0)
    assert np.count_nonzero(np.diff(held)) == len(log)  # still one step per transmission


def test_nodes_choose_the_panels_in_order(arcs_only):
    _, axes = plot_held_outputs(arcs_only, nodes=1)
    assert [ax.get_ylabel() for ax in axes] == ["sensor 2"]
    _, axes = plot_held_outputs(arcs_only, nodes=(1, 0))
    assert [ax.get_ylabel() for ax in axes] == ["sensor 2", "sensor 1"]
    _line(axes[0], r"$\bar y_{2}$")


def test_with_a_network_the_held_value_changes_when_the_packet_arrives():
    delay = 0.1
    pb = two_sensors(network=Network(Link(delay=delay)))
    result = simulate(pb, x0=X0[0], t_end=T_END, backend="scipy")
    arc = result.arc(0)
    _, axes = plot_held_outputs(result)
    assert "held values change on delivery" in axes[0].get_title()
    for i, ax in enumerate(axes):
        sent_log = result.transmissions.select(run=0, rule=i)
        arrived = result.deliveries.select(run=0, rule=i)
        assert len(arrived) >= len(sent_log) - 2 > 5
        np.testing.assert_allclose(arrived.t, sent_log.t[: len(arrived)] + delay, rtol=0, atol=1e-9)
        _, held, _ = _line(ax, rf"$\bar y_{{{i + 1}}}$")
        t_sent, sent, _ = _line(ax, "values sent")
        np.testing.assert_array_equal(t_sent, sent_log.t)
        np.testing.assert_allclose(sent, arc.x[_jump_rows(arc, sent_log), i], rtol=0, atol=1e-13)
        after = _jump_rows(arc, arrived) + 1
        np.testing.assert_allclose(held[after], sent[: len(arrived)], rtol=0, atol=1e-13)
        np.testing.assert_array_equal(np.flatnonzero(np.diff(held) != 0), after - 1)


def _with_input(t, x, u, v):
    return A @ x + np.array([0.0, u[0]]) + v


def _model_with_input(t, x, u):
    return A @ x + np.array([0.0, u[0]])


def test_noise_and_an_input_node():
    plant = Plant(f_p=_with_input, h=lambda x: x, n_x=2, n_y=2, n_u=1, n_v=2)
    observer = luenberger(_model_with_input, L=np.eye(2) * 3.0)
    noise = Sinusoid(amplitude=[0.002, 0.002], omega=30.0)
    pb = EstimationProblem(
        plant,
        observer,
        nodes=[Node((0, 1), rule(), name="both")],
        u=Sinusoid(amplitude=[1.0], omega=2.0),
        m=noise,
        input_nodes=[InputNode((0,), rule())],
    )
    result = simulate(pb, x0=X0[1], t_end=3.0, backend="scipy")
    arc = result.arc(0)
    _, axes = plot_held_outputs(result)
    assert [ax.get_ylabel() for ax in axes] == ["both", "input0"]
    for k in range(2):  # node 0 sends both outputs: two steps in its panel
        _, measured, _ = _line(axes[0], rf"$\tilde y_{{{k + 1}}}$")
        np.testing.assert_allclose(measured, arc.x[:, k] + noise(arc.t)[:, k], rtol=0, atol=1e-13)
    log = result.transmissions.select(run=0, rule=1)
    assert len(log) > 3
    t, u, _ = _line(axes[1], "$u_{1}$")
    np.testing.assert_array_equal(u, np.sin(2.0 * t))
    _, ubar, _ = _line(axes[1], r"$\bar u_{1}$")
    before = _jump_rows(arc, log)
    np.testing.assert_allclose(ubar[before + 1], np.sin(2.0 * log.t), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(_ticks(axes[1]), log.t)


def test_the_observer_copy_hold_compares_with_the_output_estimation_error():
    result = simulate(two_sensors(hold="innovation"), x0=X0[0], t_end=3.0, backend="scipy")
    arc = result.arc(0)
    _, axes = plot_held_outputs(result, nodes=0)
    _, measured, _ = _line(axes[0], r"$y_{1} - \hat y_{1}$")
    np.testing.assert_allclose(measured, arc.x[:, 0] - arc.xhat[:, 0], rtol=0, atol=1e-13)
    _, held, _ = _line(axes[0], r"$\bar y_{1}$")
    log = result.transmissions.select(run=0, rule=0)
    np.testing.assert_allclose(held[_jump_rows(arc, log) + 1], _line(axes[0], "values sent")[1], atol=1e-13)


def test_renders(arcs_only, tmp_path):
    fig, _ = plot_held_outputs(arcs_only)
    fig.savefig(tmp_path / "held.png")
    assert (tmp_path / "held.png").stat().st_size > 10_000


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"run": 2}, InputError, r"`run` must be in 0\.\.1; got 2"),
        (
            {"run": 1.0},
            InputTypeError,
            r"`run` must be an integer or a sequence of integers; got 1\.0 \(float\)",
        ),
        (
            {"nodes": 2},
            InputError,
            r"`nodes` names node 2, which does not exist: the problem has 2 output nodes \(0\.\.1\)$",
        ),
        ({"nodes": [0, -1]}, InputError, r"`nodes\[1\]` must be an integer >= 0; got -1"),
        ({"nodes": []}, InputError, r"`nodes` must name at least one node"),
        ({"nodes": [1, 1]}, InputError, r"`nodes` must not repeat an index"),
        ({"nodes": "sensor 1"}, InputTypeError, r"`nodes\[0\]` must be an integer; got 's'"),
    ],
)
def test_bad_arguments_are_named(arcs_only, kwargs, error, match):
    with pytest.raises(error, match=match):
        plot_held_outputs(arcs_only, **kwargs)


def test_input_nodes_are_counted_in_the_message():
    pb = two_sensors()
    plant = Plant(f_p=_with_input, h=lambda x: x, n_x=2, n_y=2, n_u=1, n_v=2)
    pb = EstimationProblem(
        plant,
        luenberger(_model_with_input, L=np.eye(2)),
        nodes=pb.nodes,
        input_nodes=[InputNode((0,), rule())],
    )
    result = simulate(pb, x0=X0[0], t_end=0.5, backend="scipy")
    with pytest.raises(InputError, match=r"has 2 output nodes \(0\.\.1\) and 1 input nodes \(2\.\.2\)"):
        plot_held_outputs(result, nodes=[3])


def test_a_result_with_neither_arcs_nor_grid_says_what_to_keep():
    pb = two_sensors()
    result = simulate(pb, x0=X0, t_end=0.5, save=SaveAt(steps=False), backend="scipy")
    with pytest.raises(
        InputError, match=r"kept neither arcs nor a grid of states: simulate with save=SaveAt\(steps=True\)"
    ):
        plot_held_outputs(result)
    save = SaveAt(steps=False, grid=[0.0, 0.5], max_distance="estimation_error")
    result = simulate(pb, x0=X0, t_end=0.5, save=save, backend="scipy")
    with pytest.raises(InputError, match=r"it kept only max \|x - xhat\| over its grid"):
        plot_held_outputs(result)
    with pytest.raises(InputTypeError, match=r"`result` must be an EstimationResult; got HybridSolution"):
        plot_held_outputs(result.solution)


@pytest.mark.parametrize("logy", [False, True])
def test_inter_event_times_are_the_gaps_on_a_linear_or_log_axis(arcs_only, logy):
    from etobs.estimation import inter_event_times

    _, axes = plot_inter_event_times(arcs_only, run=0, logy=logy)
    for node, ax in enumerate(axes):
        assert ax.get_yscale() == ("log" if logy else "linear")
        gaps = inter_event_times(arcs_only, 0, node)
        if gaps.size:
            drawn = [c for c in ax.collections if len(c.get_segments())]  # the stems
            heights = np.array([seg[1][1] for seg in drawn[0].get_segments()])
            np.testing.assert_array_equal(heights, gaps)


def test_inter_event_times_check_the_run(arcs_only):
    # it drew empty panels for a run that does not exist
    with pytest.raises(InputError, match=r"`run` must be in 0\.\.1; got 5"):
        plot_inter_event_times(arcs_only, run=5)


def test_a_node_that_never_sent_holds_its_first_value():
    result = simulate(two_sensors(), x0=X0[0], t_end=0.05, backend="scipy")
    assert len(result.transmissions) == 0
    arc = result.arc(0)
    _, axes = plot_held_outputs(result)
    for i, ax in enumerate(axes):
        _, held, _ = _line(ax, rf"$\bar y_{{{i + 1}}}$")
        np.testing.assert_array_equal(held, arc.x[0, i])  # ybar(0) = y(0), never updated
        assert _ticks(ax).size == 0
        assert "transmissions (0)" in [t.get_text() for t in ax.get_legend().get_texts()]
