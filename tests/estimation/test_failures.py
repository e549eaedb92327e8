"""Estimation problems that hung or gave silent wrong results (issue 14), on both solvers.

Each run now ends with a named status after a bounded number of jumps or steps, and
each failure names the function at fault; the tests assert statuses and counts, never
wall-clock time.
"""

import math

import numpy as np
import pytest

from etobs import EstimationProblem, Node, Observer, Plant, simulate
from etobs.errors import ModelError
from etobs.hybrid import SaveAt, SolverOptions
from etobs.model import Custom, DynamicRule, Linear, PeriodicRule, Quadratic, StaticRule
from etobs.model.rules import send_on_delta

BACKENDS = ["engine", "scipy"]
WRITES = "writes into one of its input arrays, which are read-only"


def _problem(f_p, rule, h=None):
    plant = Plant(f_p=f_p, h=h or (lambda x: x.copy()), n_x=1, n_y=1)
    observer = Observer(f_o=lambda t, z, u, ybar, yhat: ybar - z, n_z=1)
    return EstimationProblem(plant=plant, observer=observer, nodes=[Node((0,), rule)])


def _run(pb, t_end, backend, **options):
    return simulate(
        pb, [1.0], t_end, backend=backend, options=SolverOptions(**options), save=SaveAt(steps=False)
    )


def _cosine(t, x, u, v):
    return np.array([math.cos(t)])


def _square(t, x, u, v):
    return x * x


def _decay(t, x, u, v):
    return -x


def _stiff(t, x, u, v):
    return -1e6 * x


# ---- statuses in bounded time ----------------------------------------------------------------


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_tiny_eps_ends_zeno(backend):
    # eps = 1e-300: a transmission whenever |e| >= 1e-150, i.e. at every event the solver
    # can place. Before: a million jumps in 5e-7 s, then max_jumps (a sweep was killed)
    res = _run(_problem(_cosine, StaticRule(gamma=Quadratic(1.0), eps=1e-300)), 1.0, backend)
    assert res.status_labels() == ["zeno"]
    assert res.solution.j_final[0] < 5_000


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_finite_escape_with_transmissions_ends_with_a_jump_limit(backend):
    # x' = x^2 escapes at t = 1; the transmissions grow without bound before it (x/0.03
    # of them by x). Not Zeno in time (the jumps stay resolvable until x ~ 1e5): the jump
    # limit ends it, after 12 s on the engine with the default million
    rule = DynamicRule(gamma=Quadratic(1.0), alpha=Linear(1.0), sigma=0.5, c=0.5, b=0.5, eps=1e-3, eta0=1.0)
    res = _run(_problem(_square, rule), 10.0, backend, max_jumps=2_000)
    assert res.status_labels() == ["max_jumps"]
    assert res.solution.t_final[0] < 1.0


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("period", [1e-9, 1e-7])
def test_a_tiny_period_ends_with_the_jump_limit(backend, period):
    # PeriodicRule(1e-9) over 1 s is a billion transmissions (the audit's run was killed)
    res = _run(_problem(_decay, PeriodicRule(period)), 1.0, backend, max_jumps=2_000)
    assert res.status_labels() == ["max_jumps"]
    assert res.solution.t_final[0] == pytest.approx(2_000 * period, rel=1e-3)
    assert "many transmissions (a short period" in res.messages()[0]


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_stiff_plant_ends_with_the_step_limit(backend):
    # x' = -1e6 x: ~156,000 explicit steps per second of horizon (scipy: 75 s for 1 s)
    res = _run(_problem(_stiff, send_on_delta(0.1)), 1e4, backend, max_steps=3_000)
    assert res.status_labels() == ["max_steps"]
    assert res.solution.n_steps[0] + res.solution.n_rejected[0] <= 3_000


# ---- a trigger function that is NaN --------------------------------------------------------


def _nan_past(s):
    # finite where Custom probes it (up to 1e3), NaN from 2e3 on
    return s if s < 2e3 else math.nan


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_nan_trigger_function_ends_the_run_naming_the_guard(backend):
    # x' = 1e3 and eps = 5e3: |e| reaches 2e3 at t = 2, where gamma turns NaN. Before: the
    # node never sent again and the run "completed"
    rule = StaticRule(gamma=Custom(_nan_past), eps=5e3)
    res = _run(_problem(lambda t, x, u, v: np.full(1, 1e3), rule), 10.0, backend)
    assert res.status_labels() == ["model_error"]
    assert res.solution.t_final[0] <= 2.0 + 1e-9
    assert "guard` returned NaN" in res.messages()[0]


# ---- shapes checked at every call ----------------------------------------------------------


def _long_late(t, x, u, v):
    if t > 0.5:
        return np.array([-x[0], 0.0])
    return -x


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_wrong_length_late_in_a_run_ends_it_naming_f_p(backend):
    # checked at every call, not once at construction: no broadcast, no silent result
    res = _run(_problem(_long_late, send_on_delta(0.1)), 1.0, backend)
    assert res.status_labels() == ["model_error"]
    assert res.solution.t_final[0] <= 0.5
    assert "`f_p` returned" in res.messages()[0]
    # the reference ran the Python function: it must not send the user to itself
    assert ("run the same problem with backend='scipy'" in res.messages()[0]) == (backend == "engine")
    if backend == "scipy":
        assert (
            "`f_p` returned shape (2,); expected (1,) for one run; a model function failed on this run's "
            in (res.messages()[0])
        )


def _scalar_late(t, x, u, v):
    if t > 0.5:
        return -x[0]
    return -x


def test_a_scalar_late_in_a_run_is_refused_by_the_engine_and_ends_the_reference_run():
    pb = _problem(_scalar_late, send_on_delta(0.1))
    # numba types the function once: an array here and a float there cannot be compiled
    with pytest.raises(ModelError, match=r"^`f_p` cannot be compiled"):
        _run(pb, 1.0, "engine")
    res = _run(pb, 1.0, "scipy")
    assert res.status_labels() == ["model_error"]
    assert "`f_p` returned shape (); expected (1,) for one run" in res.messages()[0]


# ---- read-only inputs ----------------------------------------------------------------------


def _doubles_x(t, x, u, v):
    x[0] = 2.0 * x[0]
    return -x


def test_a_function_that_writes_into_its_input_is_refused_when_the_problem_is_built():
    # before: the engine's results changed (nonfinite at t = 8e-8), the reference failed
    # inside brentq with "f(a) and f(b) must have different signs"
    with pytest.raises(ModelError, match=rf"^`f_p` {WRITES}"):
        _problem(_doubles_x, send_on_delta(0.1))


def _writes_late(t, x, u, v):
    if t > 0.5:
        x[0] = 0.0
    return -x


def test_a_late_write_into_an_input_is_refused_with_the_same_words_on_both_backends():
    pb = _problem(_writes_late, send_on_delta(0.1))  # the write is not reached at t = 0
    with pytest.raises(ModelError, match=rf"^`f_p` {WRITES}"):
        _run(pb, 1.0, "engine")  # numba refuses the write when it compiles the function
    res = _run(pb, 1.0, "scipy")
    assert res.status_labels() == ["model_error"]
    assert f"`f_p` {WRITES}" in res.messages()[0]
    assert res.solution.t_final[0] <= 0.5


# ---- errors from compiling or calling a user function (issue 23) --------------------------------

_A = np.array([[0.0, 1.0], [-2.0, -0.5]])
_RULE = DynamicRule(gamma=Quadratic(5.0), alpha=Linear(2.0), sigma=10.0, c=0.01, b=1.0, eps=0.01, eta0=1.0)


def _two(f_p=None, f=None):
    """A 2-state oscillator, one node per output, a Luenberger observer on the model ``f``."""
    from etobs import luenberger

    plant = Plant(f_p=f_p or (lambda t, x, u, v: _A @ x), h=lambda x: x, n_x=2, n_y=2)
    observer = luenberger(f or (lambda t, x, u: _A @ x), L=np.eye(2) * 3.0)
    return EstimationProblem(plant, observer, [Node((0,), _RULE), Node((1,), _RULE)])


SCRIPT = """
import numpy as np
from etobs import DynamicRule, EstimationProblem, Node, Observer, Plant, Quadratic, simulate

def f_p(t, x, u, v):
    table = {"k": object()}  # numba cannot compile a dict of objects
    return -x

pb = EstimationProblem(Plant(f_p=f_p, h=lambda x: x, n_x=1, n_y=1),
                       Observer(f_o=lambda t, z, u, ybar, yhat: ybar - z, n_z=1),
                       [Node((0,), DynamicRule(gamma=Quadratic(1.0), eps=0.01))])
simulate(pb, [1.0], 1.0)
"""


@pytest.mark.parametrize("debug", ["", "1"])
def test_a_compile_error_prints_a_few_lines_and_numba_s_traceback_only_on_request(tmp_path, debug):
    import os
    import subprocess
    import sys

    script = tmp_path / "model.py"
    script.write_text(SCRIPT)
    env = {**os.environ, "ETOBS_CACHE_DIR": str(tmp_path / "cache"), "ETOBS_DEBUG": debug}
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, env=env, cwd=tmp_path)
    lines = out.stderr.splitlines()
    assert out.returncode == 1
    assert lines[-1].startswith(
        "etobs.errors.ModelError: `f_p` cannot be compiled: Untyped global name 'object'"
    )
    if debug:  # the chained numba traceback: 347 lines before this change, on every run
        assert len(lines) > 100 and "numba" in out.stderr
    else:
        assert len(lines) <= 15 and "numba" not in out.stderr


def test_the_cause_of_a_short_compile_error_stays_inspectable():
    from etobs.compile import FunctionSpec, compile_function

    def f(x):
        return {"k": object()}

    with pytest.raises(ModelError, match=r"^`h` cannot be compiled") as info:
        compile_function(f, FunctionSpec("A0", (1,), 1), "h")
    assert info.value.__cause__ is None and info.value.__suppress_context__
    assert "numba" in type(info.value.__context__).__module__


def test_a_bound_method_is_named_as_the_user_wrote_it():
    class Model:
        def f_p(self, t, x, u, v):
            return _A @ x

    pb = _two(f_p=Model().f_p)
    with pytest.raises(ModelError, match=r"^`f_p` is a bound method \(.*Model\.f_p\), whose `self`") as info:
        simulate(pb, [1.0, 0.0], 1.0, backend="engine")
    assert "USER" not in str(info.value)
    assert simulate(pb, [1.0, 0.0], 1.0, backend="scipy").ok  # the reference runs any Python


@pytest.mark.parametrize(
    "f_p, f",
    [
        (lambda t, x, u, v: [x[1], -2.0 * x[0] - 0.5 * x[1]], None),  # a list, as np.asarray takes it
        (
            lambda t, x, u, v: (x[1], -2.0 * x[0] - 0.5 * x[1]),
            lambda t, x, u: (x[1], -2.0 * x[0] - 0.5 * x[1]),
        ),
    ],
    ids=["list", "tuple in luenberger"],
)
def test_lists_and_tuples_run_on_both_backends_with_the_same_transmissions(f_p, f):
    # before: the list failed on the engine naming `store`, the tuple in luenberger blamed `f_o`
    pb = _two(f_p=f_p, f=f)
    ref = _two()
    runs = [simulate(p, [1.0, 0.0], 5.0, backend=b) for p in (pb, ref) for b in BACKENDS]
    assert all(r.ok for r in runs)
    for r in runs[1:]:
        np.testing.assert_allclose(r.transmissions.t, runs[0].transmissions.t, rtol=0, atol=1e-6)
        np.testing.assert_array_equal(r.transmissions.rule, runs[0].transmissions.rule)


COMPLEX = r"^`f_p` returned complex values; the states are real: return the real part \(np.real\)"


def test_a_complex_plant_is_refused_with_the_same_words_on_both_backends():
    # before: backend="scipy" dropped the imaginary part (a ComplexWarning) and completed
    with pytest.raises(ModelError, match=COMPLEX):
        _two(f_p=lambda t, x, u, v: _A @ x + 0j)
    from etobs.compile import FunctionSpec, compile_function
    from etobs.estimation.calls import _rows

    with pytest.raises(ModelError, match=COMPLEX):  # the engine, complex only on this path
        compile_function(lambda t, x, u, v: x * (1 + 0j), FunctionSpec("t, A0, A1, A2", (2, 0, 0), 2), "f_p")
    with pytest.raises(ModelError, match=COMPLEX):  # the reference, complex on a later state
        _rows(
            "f_p",
            2,
            lambda t, x, u, v: x + 0j,
            np.zeros(1),
            np.ones((1, 2)),
            np.zeros((1, 0)),
            np.zeros((1, 0)),
        )


@pytest.mark.parametrize("backend", BACKENDS)
def test_an_h_that_is_nan_at_the_initial_state_is_named_not_x0(backend):
    # before: "`x0` must be finite; runs [0] are not", of a finite x0
    pb = _problem(
        _decay,
        DynamicRule(gamma=Quadratic(1.0), eps=0.01),
        h=lambda x: x * math.nan if x[0] == 1.0 else x.copy(),
    )
    with pytest.raises(
        ModelError,
        match=r"^`h` \(or the noise `m`\) returned a value that is not finite at `x0`, in runs \[1\]",
    ):
        simulate(pb, [[2.0], [1.0]], 1.0, backend=backend)


def test_v_without_n_v_says_to_give_the_plant_n_v():
    from etobs import InputError, Sinusoid

    # before: "`v` has dimension 1; expected 0" and nothing more
    with pytest.raises(
        InputError, match=r"^`v` has dimension 1; expected 0 \(the plant's `n_v`\): give the plant `n_v=1`"
    ):
        EstimationProblem(
            Plant(f_p=_decay, h=lambda x: x.copy(), n_x=1, n_y=1),
            Observer(f_o=lambda t, z, u, ybar, yhat: ybar - z, n_z=1),
            [Node((0,), StaticRule(Quadratic(1.0), eps=0.01))],
            v=Sinusoid(amplitude=[0.1], omega=1.0),
        )


@pytest.mark.parametrize("backend", ["engine", "scipy"])
@pytest.mark.parametrize(
    ("blows_up", "named"), [("plant", "the plant's state x"), ("observer", "the observer's state z")]
)
def test_a_nonfinite_run_says_whether_the_plant_or_the_observer_blew_up(backend, blows_up, named):
    # issue 23: `nonfinite` did not say which part of the loop went to infinity. x' = x^2
    # and z' = z^2 from 1 escape at t = 1 (ending nonfinite, or step_underflow while the
    # state is still finite); the other part stays at most 1 in size.
    escape = lambda s: s * s  # noqa: E731
    calm = lambda s: -s  # noqa: E731
    fp, fo = (escape, calm) if blows_up == "plant" else (calm, escape)
    # y = 0: no transmission, so the blow-up is not cut short by jumps piling up (zeno)
    plant = Plant(f_p=lambda t, x, u, v: fp(x), h=lambda x: 0.0 * x, n_x=1, n_y=1)
    observer = Observer(f_o=lambda t, z, u, ybar, yhat: fo(z), n_z=1)
    rule = StaticRule(gamma=Quadratic(1.0), eps=1.0)
    pb = EstimationProblem(plant, observer, [Node((0,), rule)])
    with np.errstate(all="ignore"):
        res = simulate(pb, [1.0], 2.0, z0=[1.0], backend=backend, save=SaveAt(steps=False))
    assert res.status_labels()[0] in ("nonfinite", "step_underflow")
    (message,) = res.messages()
    assert named in message
    assert res.solution.t_final[0] <= 1.0 + 1e-6
    other = "the observer's state z" if blows_up == "plant" else "the plant's state x"
    assert other not in message.split(";")[0]
