"""Figures for a paper: names and units, ax= composition, windows, overlaid runs, sizes, vector output."""

import numpy as np
import pytest

from etobs import InputError, InputTypeError, Plant, SaveAt, simulate
from etobs.plot import (
    COLUMN_WIDTH,
    Drawn,
    paper_figure,
    paper_style,
    plot_error,
    plot_held_outputs,
    plot_hybrid_arc,
    plot_inter_event_times,
    plot_states,
    save_figure,
)
from tests.plot.models import T_END, X0, _h, _plant, named_sensors


@pytest.fixture(scope="module")
def named():
    """The oscillator of the other plot tests, its states and outputs named, with units; two runs."""
    save = SaveAt(grid=np.linspace(0, T_END, 251))
    return simulate(named_sensors(), x0=X0, t_end=T_END, save=save, backend="scipy")


def _lines(ax):
    return {ln.get_label(): ln for ln in ax.get_lines()}


def test_states_carry_the_models_names_and_units(named):
    _, axes = plot_states(named)
    assert [ax.get_ylabel() for ax in axes] == ["position [m]", "velocity [m/s]"]
    g = named.on_grid()
    for k, (ax, name) in enumerate(zip(axes, ["position", "velocity"], strict=True)):
        lines = _lines(ax)
        np.testing.assert_array_equal(lines[name].get_ydata(), g.x[0, :, k])
        np.testing.assert_array_equal(lines[f"{name} estimate"].get_ydata(), g.xhat[0, :, k])


def test_unnamed_models_keep_the_papers_symbols(arcs_and_grid):
    _, axes = plot_states(arcs_and_grid)
    assert set(_lines(axes[0])) == {"$x_{1}$", r"$\hat x_{1}$"}
    assert axes[0].get_ylabel() == ""


def test_held_outputs_and_hybrid_arc_name_the_outputs(named):
    _, axes = plot_held_outputs(named)
    assert axes[0].get_ylabel() == "sensor 1\n[m]" and axes[1].get_ylabel() == "sensor 2\n[m/s]"
    assert {"position, held", "position"} <= set(_lines(axes[0]))
    assert {"velocity, held", "velocity"} <= set(_lines(axes[1]))
    _, (ax, _) = plot_hybrid_arc(named, what="ybar")
    assert {"position, held [m]", "velocity, held [m/s]"} <= set(_lines(ax))


def test_a_two_panel_figure_composed_from_two_calls_written_as_pdf_and_svg(named, tmp_path):
    fig, (top, bottom) = paper_figure(columns=2, nrows=2)
    assert fig.get_size_inches().tolist() == [COLUMN_WIDTH[2], 1.3 * 2 + 0.4]
    states = plot_states(named, ax=top)  # one Axes for every state: overlaid, a colour each
    held = plot_held_outputs(named, ax=bottom)
    assert isinstance(states, Drawn) and states.fig is fig and held.fig is fig
    assert len(fig.axes) == 2 and list(states.axes) == [top, top]
    g = named.on_grid()
    assert [ln.get_label() for ln in states.artists["x"]] == ["position [m]", "velocity [m/s]"]
    for k, line in enumerate(states.artists["x"]):
        np.testing.assert_array_equal(line.get_ydata(), g.x[0, :, k])
        assert line.get_color() == states.artists["xhat"][k].get_color() == f"C{k}"
    assert top.get_ylabel() == "x"  # two units: they are in the legend
    ticks = held.artists["ticks"]
    assert [t.get_label() for t in ticks] == [
        f"sensor {i + 1}: transmissions ({len(named.transmission_times(0, i))})" for i in range(2)
    ]
    assert [float(t.get_ydata()[0]) for t in ticks if len(t.get_ydata())] == [0.03, 0.09]
    assert fig.texts == [] and not fig._suptitle  # the caller's figure: no title of ours
    assert top.get_xlabel() == "" and bottom.get_xlabel() == "t [s]"  # the shared time axis, once
    pdf = save_figure(fig, tmp_path / "two-panel.pdf")
    data = pdf.read_bytes()
    assert data.startswith(b"%PDF") and b"/Subtype /Image" not in data  # vector, no raster
    assert b"/FontFile2" in data  # the fonts embedded as TrueType (fonttype 42): editable text
    fig2, axes2 = paper_figure(columns=2, nrows=2)
    plot_states(named, ax=axes2[0])
    plot_held_outputs(named, ax=axes2[1])
    again = save_figure(fig2, tmp_path / "again.pdf").read_bytes()
    assert again == data  # no creation date: the same figure writes the same bytes
    svg = save_figure(fig, tmp_path / "two-panel.svg").read_text()
    assert "<svg" in svg and "position [m]" in svg  # text kept as text
    assert save_figure(fig, tmp_path / "two-panel.png", dpi=50).read_bytes().startswith(b"\x89PNG")


def test_components_choose_the_states_drawn(named):
    drawn = plot_states(named, components=[1])
    assert len(drawn.axes) == 1 and drawn.axes[0].get_ylabel() == "velocity [m/s]"
    np.testing.assert_array_equal(drawn.artists["x"][0].get_ydata(), named.on_grid().x[0, :, 1])
    with pytest.raises(InputError, match=r"`components` must be in 0\.\.1; got 2"):
        plot_states(named, components=[0, 2])


def test_a_time_window_draws_only_its_points(named):
    _, axes = plot_states(named, window=(1.0, 2.0))
    t = np.asarray(_lines(axes[0])["position"].get_xdata())
    assert t.min() >= 1.0 and t.max() <= 2.0 and t.size == 51  # grid step 0.02, both ends
    assert axes[0].get_xlim() == (1.0, 2.0)
    _, axes = plot_inter_event_times(named, window=(1.0, 2.0))
    stems = plot_inter_event_times(named, window=(1.0, 2.0)).artists["gaps"]
    times = named.transmission_times(0, 0)
    inside = times[1:][(times[1:] >= 1.0) & (times[1:] <= 2.0)]
    np.testing.assert_array_equal(stems[0].markerline.get_xdata(), inside)
    _, axes = plot_held_outputs(named, window=(1.0, 2.0))
    ticks = np.asarray(_lines(axes[0])[f"transmissions ({inside.size + (times[0] >= 1.0)})"].get_xdata())
    assert ticks.min() >= 1.0 and ticks.max() <= 2.0


def test_several_runs_are_overlaid_and_named(named):
    drawn = plot_error(named, run=[0, 1])
    g = named.on_grid()
    assert [ln.get_label() for ln in drawn.artists["error"]] == ["run 0", "run 1"]
    for r, line in enumerate(drawn.artists["error"]):
        np.testing.assert_array_equal(line.get_ydata(), g.error[r])
    assert drawn.artists["error"][0].get_color() != drawn.artists["error"][1].get_color()
    states = plot_states(named, run=[1, 0])
    assert [ln.get_label() for ln in states.artists["x"]] == [
        "position (run 1)", "velocity (run 1)", "position (run 0)", "velocity (run 0)"
    ]  # fmt: skip
    gaps = plot_inter_event_times(named, run=[0, 1]).artists["gaps"]
    assert [ln.get_label() for ln in gaps] == ["run 0", "run 1", "run 0", "run 1"]
    np.testing.assert_array_equal(gaps[3].get_xdata(), named.transmission_times(1, 1)[1:])
    held = plot_held_outputs(named, run=[0, 1], nodes=0)
    assert [ln.get_label() for ln in held.artists["held"]] == [
        "position, held (run 0)",
        "position, held (run 1)",
    ]
    arc = plot_hybrid_arc(named, run=[0, 1], what="x", components=0)
    assert [ln.get_label() for ln in arc.artists["flows"]] == ["position [m] (run 0)", "position [m] (run 1)"]


def test_paper_style_sets_a_journals_fonts_while_drawing(named):
    with paper_style() as rc:
        fig, ax = paper_figure(columns=1)
        plot_error(named, ax=ax[0])
        assert rc["pdf.fonttype"] == 42
    assert fig.get_size_inches()[0] == COLUMN_WIDTH[1]
    assert ax[0].xaxis.label.get_fontsize() == 8.0
    _, default = plot_error(named)
    assert default.xaxis.label.get_fontsize() != 8.0  # outside the block: matplotlib's default


@pytest.mark.parametrize(
    ("call", "error", "match"),
    [
        (lambda r, f: plot_states(r, ax=f.subplots(1, 3)), InputError, r"`ax` must be one Axes \(all panels "
         r"overlaid\) or 2 Axes \(one per panel\); got 3"),
        (lambda r, f: plot_states(r, ax="axes"), InputTypeError, r"`ax` must be a matplotlib Axes or a sequence "
         r"of 2; got str"),
        (lambda r, f: plot_hybrid_arc(r, ax=f.subplots()), InputError, r"`ax` must be two Axes for plot_hybrid_arc"),
        (lambda r, f: plot_error(r, window=(2.0, 1.0)), InputError, r"`window` must have t0 < t1; got \(2, 1\)"),
        (lambda r, f: plot_error(r, window=3.0), InputError, r"`window` must be a pair \(t0, t1\) of times; got 3"),
        (lambda r, f: plot_error(r, window=(0, "1")), InputTypeError, r"`window\[1\]` must be a real number"),
        (lambda r, f: plot_error(r, run=[0, 2]), InputError, r"`run` must be in 0\.\.1; got 2"),
        (lambda r, f: plot_error(r, run=[0, 0]), InputError, r"`run` must not repeat an index; got \[0, 0\]"),
        (lambda r, f: plot_error(r, run=[]), InputError, r"`run` must name at least one run index"),
        (lambda r, f: paper_figure(columns=3), InputError, r"`columns` must be 1 or 2 \(one column or the page\)"),
        (lambda r, f: paper_figure(nrows=0), InputError, r"`nrows` must be an integer >= 1; got 0"),
        (lambda r, f: paper_figure(height=0.4), InputError, r"`height` must be >= 0\.5; got 0\.4"),
        (lambda r, f: save_figure(f, "figure.png", dpi=0), InputError, r"`dpi` must be >= 1; got 0"),
        (lambda r, f: r.problem.quantities("w"), InputError, r"`variable` must be one of x, xhat, z, y, ybar, e, "
         r"u; got 'w'"),
        (lambda r, f: r.problem.plant.quantities("z"), InputError, r"`vector` must be 'x', 'y' or 'u'; got 'z'"),
        (lambda r, f: save_figure(f, "figure.eps"), InputError, r"`path` must end in one of \.pdf, \.svg, \.png; "
         r"got 'figure\.eps'"),
    ],
)  # fmt: skip
def test_bad_arguments_are_named(named, call, error, match):
    from matplotlib.figure import Figure

    with pytest.raises(error, match=match):
        call(named, Figure())


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"state_names": ["a"]}, InputError, r"`state_names` must have 2 entries, one per entry of the vector; got 1"),
        ({"output_units": "m"}, InputTypeError, r"`output_units` must be a list of 2 strings, one per entry; got 'm'"),
        ({"state_units": ["m", 2]}, InputTypeError, r"`state_units` must hold strings; entry 1 is 2 \(int\)"),
        ({"input_names": ["u"]}, InputError, r"`input_names` must have 0 entries"),
    ],
)  # fmt: skip
def test_names_and_units_are_checked(kwargs, error, match):
    with pytest.raises(error, match=match):
        Plant(f_p=_plant, h=_h, n_x=2, n_y=2, n_v=2, **kwargs)


def test_overlaid_runs_and_entries_get_a_colour_each(named):
    from matplotlib.figure import Figure

    ax = Figure().subplots()
    states = plot_states(named, run=[0, 1], ax=ax)
    colours = [ln.get_color() for ln in states.artists["x"]]
    assert len(set(colours)) == 4  # (run 0, position), (run 0, velocity), (run 1, ...)
    assert [ln.get_color() for ln in states.artists["xhat"]] == colours  # each estimate as its state
    held = plot_held_outputs(named, run=[0, 1], ax=Figure().subplots())
    assert len({ln.get_color() for ln in held.artists["held"]}) == 4
    rows = {float(t.get_ydata()[0]) for t in held.artists["ticks"] if len(t.get_ydata())}
    assert len(rows) == 4  # the ticks of each (run, node) on a row of their own
    gaps = plot_inter_event_times(named, run=[0, 1], ax=Figure().subplots())
    assert len({(ln.get_color(), ln.get_marker()) for ln in gaps.artists["gaps"]}) == 4
    arc = plot_hybrid_arc(named, run=[0, 1], what="x")
    assert len({ln.get_color() for ln in arc.artists["flows"]}) == 4


def test_a_window_between_saved_points_draws_to_its_edges_and_one_past_them_does_not_fail(
    arcs_only, grid_only
):
    drawn = plot_states(arcs_only, window=(0.5, 1.5))
    t = np.asarray(drawn.artists["x"][0].get_xdata())
    arc_t = arcs_only.arc(0).t
    assert t[0] < 0.5 < t[1] and t[-2] < 1.5 < t[-1]  # one saved point beyond each edge
    assert t[0] == arc_t[arc_t < 0.5].max() and t[-1] == arc_t[arc_t > 1.5].min()
    assert drawn.axes[0].get_xlim() == (0.5, 1.5)
    between = np.linspace(0, T_END, 101)  # grid_only's points: 0.05 apart
    empty = plot_held_outputs(grid_only, window=(between[10] + 0.01, between[10] + 0.02))
    assert all(len(ln.get_xdata()) == 2 for ln in empty.artists["held"])  # the points either side
    beyond = plot_held_outputs(grid_only, window=(T_END + 1.0, T_END + 2.0))
    # no crash (it raised IndexError): the last saved point only, the xlim shows the empty window
    assert [list(ln.get_xdata()) for ln in beyond.artists["held"]] == [[T_END, T_END]] * 2
    assert beyond.axes[0].get_xlim() == (T_END + 1.0, T_END + 2.0)


def test_drawn_pickles_and_copies_with_its_artists(named):
    import copy
    import pickle

    drawn = plot_error(named)
    for other in (pickle.loads(pickle.dumps(drawn)), copy.copy(drawn), copy.deepcopy(drawn)):
        assert isinstance(other, Drawn) and set(other.artists) == {"error"}
        np.testing.assert_array_equal(other.artists["error"][0].get_ydata(), named.on_grid().error[0])
