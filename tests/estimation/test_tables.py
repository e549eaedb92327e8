"""Tidy data out: ``EstimationResult.to_pandas`` / ``to_xarray``, the short reprs and ``simulate``'s progress.

Every table is checked against an independent computation: the metrics of
:mod:`etobs.estimation.metrics`, the saved arrays, or the model's own functions evaluated
on the full hybrid arc (``SaveAt(steps=True)``) just before each transmission.
"""

import subprocess
import sys

import numpy as np
import pytest

from etobs import DynamicRule, Linear, Link, Network, PeriodicRule, Quadratic, SaveAt, simulate
from etobs.errors import InputError, InputTypeError
from etobs.estimation import (
    max_estimation_error,
    min_inter_event_time,
    transmission_counts,
)
from etobs.examples import robot_arm
from etobs.model import InputNode, StaticRule
from tests.estimation import linear

X0 = np.array([[1.0, -0.5], [-2.0, 1.0]])
Z0 = np.zeros(2)
RULE = DynamicRule(gamma=Quadratic(4.0), alpha=Linear(1.0), sigma=2.0, c=0.2, b=1.0, eps=0.01, eta0=0.1)
GRID = np.linspace(0.0, 5.0, 251)


@pytest.fixture(scope="module")
def arm():
    """The robot arm (two 1-output nodes), two runs with arcs and a grid."""
    return simulate(robot_arm(), [[3, 2, 3, -2], [1, 0, 0, 0]], 5.0, save=SaveAt(steps=True, grid=GRID))


@pytest.fixture(scope="module")
def with_input():
    """The linear oscillator with an input node (section 7.3)."""
    pb = linear.problem(RULE, input_nodes=[InputNode((0,), StaticRule(gamma=Linear(1.0), eps=0.1), name="u")])
    return simulate(pb, X0, 5.0, z0=Z0, save=SaveAt(steps=True, grid=GRID))


def _pre_jump_states(res, table):
    """The state on the arc just before each transmission of ``table`` (the row at ``(t, j)``)."""
    out = []
    for run, t, j in zip(table["run"], table["t"], table["j"], strict=True):
        arc = res.solution.arcs[run]
        k = np.flatnonzero((arc.t == t) & (arc.j == j))
        assert k.size == 1, (run, t, j)
        out.append(arc.x[k[0]])
    return np.array(out)


# -- transmissions ----------------------------------------------------------------------


def test_transmissions_table_counts_and_sent_values_match_the_arc(arm):
    df = arm.to_pandas("transmissions")
    pb = arm.problem
    assert list(df.columns) == ["run", "node", "node_name", "kind", "t", "j", "sent_y0", "sent_y1"]
    assert str(df["run"].dtype) == "int64" and str(df["node"].dtype) == "int64"
    assert str(df["node_name"].dtype) == "category" and df["t"].dtype == float
    counts = df.groupby(["run", "node"]).size().unstack(fill_value=0).to_numpy()
    np.testing.assert_array_equal(counts, transmission_counts(arm))
    assert counts.min() > 2  # something to compare
    assert list(df["node_name"].cat.categories) == ["sensor 1", "sensor 2"]
    # the value sent is ytilde_i = h(x)_i + m_i(t) just before the jump, eq. (5) and (46)
    x = _pre_jump_states(arm, df)[:, pb.layout.x]
    y = np.array([pb.plant.h(xi) for xi in x]) + pb.m(df["t"].to_numpy())
    assert np.ptp(pb.m(df["t"].to_numpy())) > 1e-3  # the arm's noise is in what is sent
    for i, nd in enumerate(pb.nodes):
        rows = (df["node"] == i).to_numpy()
        for k in range(pb.plant.n_y):
            col = df[f"sent_y{k}"].to_numpy()[rows]
            if k in nd.outputs:
                np.testing.assert_allclose(col, y[rows, k], rtol=1e-12, atol=1e-12)
            else:
                assert np.all(np.isnan(col))  # another node's output


def test_both_solvers_log_the_values_sent():
    """The engine and the scipy reference fill the transmissions table alike."""
    tables = [
        simulate(robot_arm(), [3, 2, 3, -2], 5.0, save=SaveAt(steps=False), backend=b).to_pandas(
            "transmissions"
        )
        for b in ("engine", "scipy")
    ]
    assert len(tables[0]) == len(tables[1]) > 5
    np.testing.assert_array_equal(tables[0]["node"], tables[1]["node"])
    cols = ["t", "sent_y0", "sent_y1"]
    np.testing.assert_allclose(
        tables[0][cols], tables[1][cols], rtol=0, atol=1e-5
    )  # event times within ~1e-7 s


def test_the_transmission_log_is_indexable_and_names_what_it_logged(arm):
    log = arm.transmissions
    assert log.names == ("sent_y0", "sent_y1")
    df = arm.to_pandas("transmissions")
    row = log[3]
    assert (row.run, row.rule, row.t, row.j) == tuple(df.loc[3, ["run", "node", "t", "j"]])
    own = f"sent_y{row.rule}"  # each node sends its one output
    assert row.x[log.names.index(own)] == df.loc[3, own]
    assert log.to_pandas().columns.tolist() == ["run", "rule", "t", "j", "sent_y0", "sent_y1"]


def test_transmissions_table_window_and_node_numbering(arm):
    full = arm.to_pandas("transmissions")
    part = arm.to_pandas("transmissions", window=(2.0, 3.0))
    assert len(part) == int(transmission_counts(arm, (2.0, 3.0)).sum()) > 0
    assert part["t"].between(2.0, 3.0).all()
    assert set(part["t"]) <= set(full["t"])
    assert full.attrs["node_names"] == ["sensor 1", "sensor 2"]  # node 0 is the paper's sensor 1


def test_transmissions_table_of_nodes_sharing_a_name():
    # a name is a label, not a key: two nodes named alike (or a name equal to another
    # node's default) once crashed the table with pandas' "categories must be unique"
    from dataclasses import replace

    pb = robot_arm()
    pb = replace(pb, nodes=[replace(n, name="s") for n in pb.nodes])
    res = simulate(pb, [3, 2, 3, -2], 5.0)
    df = res.to_pandas("transmissions")
    assert list(df["node_name"].cat.categories) == ["s"]
    assert (df["node_name"] == "s").all() and set(df["node"]) == {0, 1}


def test_transmissions_table_of_an_input_node_holds_u(with_input):
    res = with_input
    df = res.to_pandas("transmissions")
    assert list(df.columns)[-2:] == ["sent_y0", "sent_u0"]
    counts = df.groupby(["run", "node"]).size().unstack(fill_value=0).to_numpy()
    np.testing.assert_array_equal(counts, transmission_counts(res, nodes="all"))
    inputs = df[df["kind"] == "input"]
    assert (inputs["node"] == 1).all() and (inputs["node_name"] == "u").all() and len(inputs) > 2
    np.testing.assert_allclose(inputs["sent_u0"], np.sin(inputs["t"]), rtol=0, atol=1e-12)  # u = sin t
    assert inputs["sent_y0"].isna().all()
    outputs = df[df["kind"] == "output"]
    x = _pre_jump_states(res, outputs)[:, res.problem.layout.x]
    np.testing.assert_allclose(outputs["sent_y0"], x @ linear.C[0], rtol=1e-12, atol=1e-12)
    assert outputs["sent_u0"].isna().all()


def test_transmissions_table_with_the_observer_copy_holds_what_was_sent():
    """Remark 3: a node sends ytilde_i - yhat_i, not ytilde_i."""
    res = simulate(linear.problem(RULE, hold="innovation"), X0, 5.0, z0=Z0, save=SaveAt(steps=True))
    df = res.to_pandas("transmissions")
    assert len(df) > 2
    lay = res.problem.layout
    q = _pre_jump_states(res, df)
    sent = q[:, lay.x] @ linear.C[0] - q[:, lay.z] @ linear.C[0]
    np.testing.assert_allclose(df["sent_y0"], sent, rtol=1e-12, atol=1e-12)


def test_transmissions_table_with_a_network_has_one_row_per_packet_sent():
    pb = linear.problem(PeriodicRule(0.05), network=Network(Link(delay=0.01, loss=0.3), seed=3))
    res = simulate(pb, X0, 3.0, z0=Z0, save=SaveAt(steps=True))
    df = res.to_pandas("transmissions")
    stats = res.network_stats()
    assert stats["lost"].sum() > 0  # some rows are packets that never arrived
    np.testing.assert_array_equal(df.groupby("run").size().to_numpy(), stats["sent"][:, 0])
    assert (df["node"] == 0).all()  # the delivery rules are not transmissions
    x = _pre_jump_states(res, df)[:, res.problem.layout.x]
    np.testing.assert_allclose(df["sent_y0"], x @ linear.C[0], rtol=1e-12, atol=1e-12)
    summary = res.to_pandas("summary")
    for key in ("lost", "overflow", "stale", "in_flight", "applied"):
        np.testing.assert_array_equal(summary[f"{key}_node0"], stats[key][:, 0])


# -- summary ----------------------------------------------------------------------------


def test_summary_reuses_the_metrics(arm):
    df = arm.to_pandas("summary")
    assert list(df["run"]) == [0, 1]
    assert list(df["status"]) == arm.status_labels() and str(df["status"].dtype) == "category"
    assert list(df["message"]) == arm.messages()
    assert (df["backend"] == arm.backend).all()
    counts, gaps = transmission_counts(arm), min_inter_event_time(arm)
    for i in range(2):
        np.testing.assert_array_equal(df[f"transmissions_node{i}"], counts[:, i])
        np.testing.assert_array_equal(df[f"min_inter_event_time_node{i}"], gaps[:, i])
    for b in range(2):  # and from the log itself
        for i in range(2):
            assert df.loc[b, f"min_inter_event_time_node{i}"] == np.diff(arm.transmission_times(b, i)).min()
    np.testing.assert_array_equal(df["max_error"], max_estimation_error(arm, (0.0, 5.0)))
    last = np.array([a.x[-1] for a in arm.solution.arcs])  # the arcs' last states, psi = z[:n_x]
    np.testing.assert_allclose(df["final_error"], np.linalg.norm(last[:, :4] - last[:, 4:8], axis=1))
    win = arm.to_pandas("summary", window=(1.0, 2.0))
    np.testing.assert_array_equal(win["transmissions_node0"], transmission_counts(arm, (1.0, 2.0))[:, 0])
    np.testing.assert_array_equal(win["max_error"], max_estimation_error(arm, (1.0, 2.0)))
    assert win.attrs["window"] == (1.0, 2.0) and win.attrs["max_error_grid"] == "251 points on [0, 5]"


def test_summary_counts_input_nodes_after_the_outputs(with_input):
    df = with_input.to_pandas("summary")
    np.testing.assert_array_equal(
        df[["transmissions_node0", "transmissions_node1"]].to_numpy(),
        transmission_counts(with_input, nodes="all"),
    )
    assert df.attrs["node_kinds"] == ["output", "input"]


def test_summary_without_a_grid_has_no_max_error_and_with_only_the_max_keeps_it():
    pb = linear.problem(RULE)
    arcs = simulate(pb, X0, 2.0, z0=Z0)
    assert "max_error" not in arcs.to_pandas("summary").columns
    only_max = simulate(
        pb, X0, 2.0, z0=Z0, save=SaveAt(steps=False, grid=GRID[:101], max_distance="estimation_error")
    )
    np.testing.assert_array_equal(only_max.to_pandas()["max_error"], only_max.solution.grid_max.value)


# -- grid -------------------------------------------------------------------------------


def test_grid_table_is_the_saved_grid_in_long_form(arm):
    df = arm.to_pandas("grid")
    tr = arm.on_grid()
    assert list(df.columns) == ["run", "t", "j", "variable", "component", "value", "name", "unit"]
    # each row names its quantity as the model does (the robot arm names its states and outputs)
    x = df[(df["variable"] == "x") & (df["run"] == 1)]
    assert list(x["name"][:5]) == [
        "motor angle",
        "motor velocity",
        "link angle",
        "link velocity",
        "motor angle",
    ]
    assert list(x["unit"][:4]) == ["rad", "rad/s", "rad", "rad/s"]
    assert set(df[df["variable"] == "ybar"]["name"]) == {"motor angle", "motor velocity"}
    assert list(df[(df["variable"] == "eta")]["name"][:2]) == ["sensor 1", "sensor 2"]
    assert set(df[df["variable"].isin(["eta", "error"])]["unit"]) == {""}
    assert list(df["variable"].cat.categories) == ["x", "z", "xhat", "ybar", "e", "eta", "error"]
    sizes = {"x": 4, "z": 4, "xhat": 4, "ybar": 2, "e": 2, "eta": 2, "error": 1}
    assert len(df) == 2 * GRID.size * sum(sizes.values())
    for name, k in sizes.items():
        part = df[df["variable"] == name]
        back = part.pivot_table(index=["run", "t"], columns="component", values="value").to_numpy()
        want = np.asarray(tr.error if name == "error" else getattr(tr, name)).reshape(-1, k)
        np.testing.assert_array_equal(back, want)
    x0 = df[(df["variable"] == "x") & (df["component"] == 0)]
    np.testing.assert_array_equal(x0["j"], tr.j.reshape(-1))
    np.testing.assert_array_equal(x0["t"], np.tile(GRID, 2))


def test_grid_table_variables_and_window(arm):
    df = arm.to_pandas("grid", variables=["xhat", "x"], window=(1.0, 2.0))
    assert set(df["variable"].unique()) == {"x", "xhat"}
    assert df["t"].between(1.0, 2.0).all()
    assert df["t"].nunique() == int(np.sum((GRID >= 1.0) & (GRID <= 2.0)))
    assert len(arm.to_pandas("grid", variables="error")) == 2 * GRID.size


def test_to_pandas_refuses_what_it_cannot_give(arm):
    with pytest.raises(
        InputError, match=r"`table` must be one of \('summary', 'transmissions', 'grid'\); got 'arcs'"
    ):
        arm.to_pandas("arcs")
    with pytest.raises(InputError, match=r"`variables` selects the grid table's variables; table 'summary'"):
        arm.to_pandas("summary", variables=["x"])
    with pytest.raises(InputError, match=r"`variables` must be names from .*'y' unknown"):
        arm.to_pandas("grid", variables=["x", "y"])
    with pytest.raises(
        InputTypeError, match=r"`variables` must be a name or a list of names from .*; got int"
    ):
        arm.to_pandas("grid", variables=3)
    with pytest.raises(InputError, match=r"`variables` must be names from .*got \[\]"):
        arm.to_pandas("grid", variables=[])
    with pytest.raises(InputError, match=r"`window` must satisfy t_start <= t_stop"):
        arm.to_pandas("transmissions", window=(2.0, 1.0))


def test_grid_table_and_dataset_need_a_grid():
    pb = linear.problem(RULE)
    arcs = simulate(pb, X0, 1.0, z0=Z0)
    only_max = simulate(pb, X0, 1.0, z0=Z0, save=SaveAt(grid=GRID[:51], max_distance="estimation_error"))
    for res, msg in (
        (arcs, r"this result kept no grid: simulate with save=SaveAt\(grid=...\)"),
        (only_max, r"kept only max \|x - xhat\| over its grid"),
    ):
        with pytest.raises(InputError, match=msg):
            res.to_pandas("grid")
        with pytest.raises(InputError, match=msg):
            res.to_xarray()


# -- xarray -----------------------------------------------------------------------------


def test_to_xarray_dims_coords_and_values(arm):
    ds = arm.to_xarray()
    tr = arm.on_grid()
    assert dict(ds.sizes) == {
        "run": 2,
        "time": GRID.size,
        "state": 4,
        "observer_state": 4,
        "output": 2,
        "node": 2,
    }
    assert ds["x"].dims == ("run", "time", "state") and ds["xhat"].dims == ("run", "time", "state")
    assert ds["z"].dims == ("run", "time", "observer_state")
    assert ds["ybar"].dims == ds["e"].dims == ("run", "time", "output")
    assert ds["eta"].dims == ("run", "time", "node") and ds["error"].dims == ("run", "time")
    for name in ("x", "z", "xhat", "ybar", "e", "eta", "error", "j"):
        np.testing.assert_array_equal(ds[name].to_numpy(), getattr(tr, name))
    np.testing.assert_array_equal(ds["time"], GRID)
    assert list(ds["status"].to_numpy()) == arm.status_labels()
    assert list(ds["node_name"].to_numpy()) == ["sensor 1", "sensor 2"]
    assert ds.attrs["backend"] == arm.backend and ds.attrs["t_span"] == (0.0, 5.0)
    # a run picked by its label, a node by name
    sel = ds["eta"].sel(run=1).swap_dims(node="node_name").sel(node_name="sensor 2")
    np.testing.assert_array_equal(sel.to_numpy(), tr.eta[1, :, 1])
    # the model's names and units as coordinates: a state picked by name
    assert list(ds["state_name"].to_numpy()) == [
        "motor angle",
        "motor velocity",
        "link angle",
        "link velocity",
    ]
    assert list(ds["state_unit"].to_numpy()) == ["rad", "rad/s", "rad", "rad/s"]
    assert list(ds["output_name"].to_numpy()) == ["motor angle", "motor velocity"]
    assert list(ds["observer_state_unit"].to_numpy()) == ["rad", "rad/s", "rad", "rad/s"]
    link = ds["x"].sel(run=0).swap_dims(state="state_name").sel(state_name="link angle")
    np.testing.assert_array_equal(link.to_numpy(), tr.x[0, :, 2])


def test_unnamed_models_keep_the_symbols_and_no_units(with_input):
    ds = with_input.to_xarray()
    assert with_input.to_pandas("transmissions").attrs["quantities"] == {"sent_y0": "y_1", "sent_u0": "u_1"}
    assert list(ds["state_name"].to_numpy()) == ["x_1", "x_2"] and set(ds["state_unit"].to_numpy()) == {""}
    assert list(ds["observer_state_name"].to_numpy()) == [
        f"z_{k + 1}" for k in range(ds.sizes["observer_state"])
    ]
    grid = with_input.to_pandas("grid", variables="x")
    assert list(grid["name"][:2]) == ["x_1", "x_2"] and set(grid["unit"]) == {""}


def test_transmissions_table_names_what_each_column_sent(arm):
    df = arm.to_pandas("transmissions")
    assert df.attrs["quantities"] == {"sent_y0": "motor angle [rad]", "sent_y1": "motor velocity [rad/s]"}


# -- reprs ------------------------------------------------------------------------------


def test_reprs_are_a_few_lines(arm):
    """A 2-run 5-s result's repr was 37 kB (every array printed); now a few lines."""
    text = repr(arm)
    assert len(text) < 800 and len(text.splitlines()) <= 10, text
    assert "2 completed" in text and "0 'sensor 1':" in text and "engine" in text
    assert "full arcs" in text and "251 points" in text
    html = arm._repr_html_()
    assert len(html) < 2000 and html.startswith("<table>") and "sensor 1" in html
    for tr in (arm.on_grid(), arm.arc(0)):
        assert len(repr(tr)) < 400 and len(repr(tr).splitlines()) <= 4
        assert "<table>" in tr._repr_html_()
    assert "2 runs x 251 grid points" in repr(arm.on_grid()) and "one arc of" in repr(arm.arc(0))


def test_repr_names_at_most_eight_nodes():
    from etobs import EstimationProblem, Node, Observer, Plant

    n = 12
    pb = EstimationProblem(
        Plant(f_p=lambda t, x, u, v: -x, h=lambda x: x, n_x=n, n_y=n),
        Observer(f_o=lambda t, z, u, ybar, yhat: ybar - z, n_z=n),
        nodes=[Node((i,), PeriodicRule(0.5)) for i in range(n)],
    )
    res = simulate(pb, np.ones(n), 1.0, save=SaveAt(steps=False))
    assert "(4 more nodes)" in repr(res) and len(repr(res)) < 800


# -- progress ---------------------------------------------------------------------------


def test_progress_bar_shows_the_simulated_time_when_forced_on(capsys):
    pb = linear.problem(RULE)
    X = np.random.default_rng(5).uniform(-2, 2, (19, 2))
    on = simulate(pb, X, 0.5, z0=Z0, progress=True)
    err = capsys.readouterr().err
    assert "simulate: 100%" in err and "t = 0.5 of 0.5 s simulated (mean of the runs)" in err
    off = simulate(pb, X, 0.5, z0=Z0, progress=False)
    assert capsys.readouterr().err == ""
    # solved while watched (with a bar) or not: the same numbers
    for key in ("run", "rule", "t", "j", "x"):
        np.testing.assert_array_equal(getattr(on.transmissions, key), getattr(off.transmissions, key))
    simulate(pb, X[:1], 0.5, z0=Z0, progress=True, backend="scipy")
    err = capsys.readouterr().err
    assert "simulate: 100%" in err and "t = 0.5 of 0.5 s simulated," in err


def test_progress_is_off_when_stderr_is_not_a_terminal(capsys):
    simulate(linear.problem(RULE), X0, 0.5, z0=Z0)  # capsys's stderr is not a terminal
    assert capsys.readouterr().err == ""


def test_progress_must_be_none_or_a_bool():
    with pytest.raises(
        InputError,
        match=r"`progress` must be None \(a bar when stderr is a terminal\), True or False; got str 'yes'",
    ):
        simulate(linear.problem(RULE), X0, 0.5, z0=Z0, progress="yes")


def test_import_etobs_loads_neither_pandas_nor_xarray():
    code = (
        "import sys, etobs, etobs.estimation; print(sorted({'pandas', 'xarray', 'tqdm'} & set(sys.modules)))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120
    )
    assert out.stdout.strip() == "[]"
