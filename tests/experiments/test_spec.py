import pytest

from etobs.experiments import SpecError, load_spec, parse_spec
from etobs.experiments.table1 import table1_spec

from .conftest import raw_spec


def test_table1_spec_is_the_paper_table():
    spec = load_spec("examples/table1.toml")
    assert spec == table1_spec()
    assert len(spec.rows) == 13 and [s.name for s in spec.scenarios] == ["with_v_m", "without_v_m"]
    assert spec.n_runs == 2600
    assert spec.rows[12] == {
        "sigma": [600.0, 800.0],
        "eps": [10.0, 10.0],
        "a": [2.0, 3.0],
        "ell": [100.0, 100.0],
    }
    x0 = spec.initial_states.draw()
    assert x0.shape == (100, 4) and x0[:, 0].max() <= 20 and x0[:, 1].max() <= 10


def test_grid_is_a_cartesian_product():
    raw = raw_spec()
    del raw["rows"]
    raw["grid"] = {"k": [1.0, 2.0, 3.0], "eps": [0.1, 0.2]}
    spec = parse_spec(raw)
    assert len(spec.rows) == 6 and spec.rows[1] == {"k": 1.0, "eps": 0.2}


def test_with_runs_and_seed():
    spec = parse_spec(raw_spec()).with_runs(9, 3)
    assert spec.initial_states.runs == 9 and spec.initial_states.seed == 3


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"colour": 1}, r"unknown key `colour`; allowed top-level keys: execution, grid, horizon"),
        ({"horizon": {"t_end": 3.0, "dt": 1}}, r"unknown key `horizon.dt`"),
        ({"horizon": {"t_end": -1.0}}, r"`horizon.t_end` must be > 0; got -1.0"),
        ({"horizon": {"t_end": "30"}}, r"`horizon.t_end` must be a number; got '30'"),
        ({"horizon": {}}, r"missing key `horizon.t_end`"),
        (
            {"initial_states": {"low": [0], "high": [1], "runs": 0, "seed": 1}},
            r"`initial_states.runs` must be >= 1; got 0",
        ),
        (
            {"initial_states": {"low": [0], "high": [1], "runs": 2.5, "seed": 1}},
            r"`initial_states.runs` must be an integer; got 2.5",
        ),
        (
            {"initial_states": {"low": [0, 0], "high": [1], "runs": 2, "seed": 1}},
            r"`initial_states.low` has 2 entries but `initial_states.high` has 1",
        ),
        (
            {"initial_states": {"low": [2], "high": [1], "runs": 2, "seed": 1}},
            r"`initial_states.high` must be >= `initial_states.low`",
        ),
        (
            {"metrics": {"error_window": [3, 2]}},
            r"`metrics.error_window` must satisfy start <= stop; got \[3, 2\]",
        ),
        ({"metrics": {"error_window": 20}}, r"`metrics.error_window` must be a pair \[start, stop\]; got 20"),
        ({"solver": {"rtol": 0.0}}, r"`solver`: `rtol` must be >= 1e-14; got 0"),
        ({"solver": {"tolerance": 1e-3}}, r"unknown key `solver.tolerance`"),
        ({"scenarios": [{"name": "a"}, {"name": "a"}]}, r"`scenarios\[1\].name` repeats 'a'"),
        ({"scenarios": [{"noise": True}]}, r"missing key `scenarios\[0\].name`"),
        ({"scenarios": [{"name": "a b"}]}, r"`scenarios\[0\].name` must be a non-empty name"),
        ({"grid": {"k": [1]}}, r"give either `rows` or `grid`, not both"),
        ({"rows": []}, r"`rows` must be a non-empty array of tables"),
        ({"system": {"factory": 3}}, r"`system.factory` must be a string; got 3"),
        ({"execution": {"workers": 3}}, r"unknown key `execution.workers`"),
        (
            {"execution": {"backend": "gpu"}},
            r"`execution.backend` must be one of \('auto', 'engine', 'scipy'\) "
            r"\(or 'numba' for 'engine'\); got 'gpu'",
        ),
    ],
)
def test_bad_specs_name_the_key(change, match):
    with pytest.raises(SpecError, match=match):
        parse_spec(raw_spec(**change))


def test_bad_files(tmp_path):
    with pytest.raises(SpecError, match=r"spec file '.*nope.toml' does not exist"):
        load_spec(tmp_path / "nope.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("name = [")
    with pytest.raises(SpecError, match=r"spec file '.*bad.toml' is not valid TOML"):
        load_spec(bad)


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"rows": [{"run": 1}]}, r"parameter `rows\[0\].run` clashes with a result column; rename it"),
        ({"scenarios": [{"name": "a", "status": 1}]}, r"parameter `scenarios\[0\].status` clashes"),
        ({"system": {"factory": "x:y", "fixed": {"x0_1": 2}}}, r"parameter `system.fixed.x0_1` clashes"),
        (
            {"metrics": {"error_window": [2.0, 4.0]}},
            r"`metrics.error_window` must lie within \[0, horizon.t_end = 3\]",
        ),
        (
            {"metrics": {"transmissions_window": [-1.0, 3.0]}},
            r"`metrics.transmissions_window` must lie within",
        ),
        ({"execution": {"chunk_size": 0}}, r"`execution.chunk_size` must be >= 1; got 0"),
        # sizes that ran out of memory: every run was listed, the grid was allocated in each chunk
        (
            {"initial_states": {"low": [0], "high": [1], "runs": 10**12, "seed": 1}},
            r"`rows` x `scenarios` \(4 groups\) x `initial_states.runs` = 1000000000000 \(or --runs\) make "
            r"4e\+12 runs; at most 1e\+07 in one experiment: split it",
        ),
        (
            {"rows": None, "grid": {"a": list(range(100)), "b": list(range(100)), "c": list(range(300))}},
            r"`grid` x `scenarios` \(6e\+06 groups\) x `initial_states.runs` = 5",
        ),
        (
            {"metrics": {"error_window": [2.0, 3.0], "error_grid_step": 1e-12}},
            r"`metrics.error_grid_step` = 1e-12 gives 1e\+12 grid points on `metrics.error_window`; at most "
            r"1e\+07: use a step >= 1e-07",
        ),
    ],
)
def test_more_bad_specs(change, match):
    raw = raw_spec(**change)
    if raw.get("rows", ()) is None:
        del raw["rows"]
    with pytest.raises(SpecError, match=match):
        parse_spec(raw)


def _with_z0(z0):
    return raw_spec(initial_states={"low": [-1.0], "high": [1.0], "runs": 2, "seed": 7, "z0": z0})


@pytest.mark.parametrize(
    ("z0", "match"),
    [
        (
            [],
            r"^`initial_states.z0` must be a non-empty list of numbers \(one per observer state\); got \[\]",
        ),
        (0.5, r"^`initial_states.z0` must be a non-empty list of numbers .*; got 0.5"),
        ([float("inf")], r"^`initial_states.z0\[0\]` must be finite; got inf"),
        (["a"], r"^`initial_states.z0\[0\]` must be a number; got 'a'"),
    ],
)
def test_a_bad_observer_initial_state_names_its_key(z0, match):
    with pytest.raises(SpecError, match=match):
        parse_spec(_with_z0(z0))


def test_an_observer_initial_state_of_the_wrong_size_is_refused_before_any_run():
    # the scalar observer has n_z = 1: two entries are one too many
    with pytest.raises(
        SpecError,
        match=r"^`initial_states.z0` has 2 entries but the observer has n_z = 1; expected 1 numbers$",
    ):
        parse_spec(_with_z0([0.0, 0.0])).check()
    parse_spec(_with_z0([0.0])).check()


def test_the_observer_initial_state_is_simulated_and_part_of_the_key(tmp_path):
    from etobs import SaveAt, max_estimation_error, simulate
    from etobs.experiments import run_sweep
    from etobs.experiments.store import task_key

    spec = parse_spec(_with_z0([50.0]))
    res = run_sweep(spec, tmp_path / "z", executor="serial", progress=False)
    plain = parse_spec(raw_spec(initial_states={"low": [-1.0], "high": [1.0], "runs": 2, "seed": 7}))
    assert task_key(spec, 0) != task_key(plain, 0)  # never mixed with runs from z0 = 0
    x0, grid, window = spec.initial_states.draw(), spec.metrics.grid(), spec.metrics.error_window

    def error(z0):
        sim = simulate(spec.problem(0), x0, spec.t_end, z0=z0, options=spec.options, save=SaveAt(grid=grid))
        return max_estimation_error(sim, window)

    first = sorted(
        (r for r in res.runs if r["row"] == 0 and r["scenario"] == "coarse"), key=lambda r: r["run"]
    )
    assert [r["error"] for r in first] == pytest.approx(error([50.0]).tolist(), rel=1e-6)
    assert [r["error"] for r in first] != pytest.approx(error([0.0]).tolist(), rel=1e-2)  # z0 matters here
