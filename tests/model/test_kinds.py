"""The registries of kinds, walked: every rule kind and K-function kind has all its forms, and they agree.

Each kind of :data:`etobs.formulas.RULE_KINDS` is built with numbers inside its declared
limits (nothing here is written per kind), simulated on every backend on a problem where
it sends, and checked against its own formulas evaluated in plain Python at every
transmission; run in the sensor node against the model object; and sent through each
spec format that names kinds (the sensor spec, the comparison spec) and the docs' table.
A kind added to a registry without its class, its engine form, its sensor form or its
spec name fails here.
"""

import re
from dataclasses import fields, replace
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from etobs import EstimationProblem, Node, Observer, Plant, SaveAt, simulate
from etobs import formulas as fm
from etobs._spec import SpecError
from etobs.errors import InputError
from etobs.estimation import _model_source as ms
from etobs.experiments.compare_spec import RULE_KINDS as SPEC_KINDS
from etobs.experiments.compare_spec import _rule
from etobs.model.functions import Custom, k_classes
from etobs.model.rules import KindRule, engine_form_of, rule_classes
from etobs.runtime.sampled_rule import RuleSpecError, SampledRule

DOCS = Path(__file__).parents[2] / "docs" / "extensions.md"
KINDS = list(fm.RULE_KINDS)
SLOPE, X0, T_END = 2.0, 1.0, 10.0


def sample(n: fm.Number) -> float:
    """A value inside the number's limits."""
    lo = 0.0 if n.lower is None else n.lower
    return (lo + n.upper) / 2 if n.upper is not None else lo + 0.5


def k_function(j: int):
    """The ``j``-th K-function of the samples: each K-function kind of etobs in turn."""
    classes = list(k_classes().values())
    cls = classes[j % len(classes)]
    return cls(*[1.5 + sample(n) + 0.25 * i for i, n in enumerate(cls.kind.numbers)])


def rule_of(name: str, shift: int = 0) -> KindRule:
    """A rule of kind ``name`` built from its descriptor alone.

    Slot ``j`` holds the K-function kind ``j + shift`` (so that the shifts put every
    K-function kind in every slot); with an odd ``shift`` a slot that allows a number has one.
    """
    kind = fm.RULE_KINDS[name]
    args: dict[str, object] = {
        slot.name: 0.7 if slot.constant and shift % 2 else k_function(j + shift)
        for j, slot in enumerate(kind.slots)
    }
    args |= {n.name: sample(n) for n in kind.numbers}
    if kind.initial is not None:
        args[kind.initial] = 0.5
    return rule_classes()[name](**args)


def ramp(rule) -> EstimationProblem:
    """``x' = 2``, ``y = x``: the gap grows as ``2 (t - t_j)`` after each transmission."""
    plant = Plant(f_p=lambda t, x, u, v: np.full_like(x, SLOPE), h=lambda x: x, n_x=1, n_y=1)
    observer = Observer(f_o=lambda t, z, u, ybar, yhat: np.zeros_like(z), n_z=1)
    return EstimationProblem(plant=plant, observer=observer, nodes=[Node((0,), rule)])


def by_formula(kind: fm.RuleKind, what: str, rule, e: float, y: float, s: float) -> float:
    """The kind's formula ``what`` in plain Python floats (no numpy, no engine)."""

    def value(arg: str) -> float:
        if arg in ("e", "y", "s"):
            return {"e": e, "y": y, "s": s}[arg]
        split = fm.split_arg(arg)
        if split is None:
            return float(getattr(rule, arg))
        fn = getattr(rule, split[0])
        at = value(split[1])
        if isinstance(fn, float):
            return fn
        k, k1, k2, _ = fn.engine_form()
        return float(k.value(k1, k2, at))

    formula = getattr(kind, what)
    return float(formula.fn(*(value(a) for a in formula.args)))


# ---- the registries: every kind has its class and its forms --------------------------


@pytest.mark.parametrize("name", KINDS)
def test_every_rule_kind_has_its_class_and_its_forms(name):
    kind, cls = fm.RULE_KINDS[name], rule_classes()[name]
    assert cls.kind is kind and kind.name == name
    own = {f.name for f in fields(cls)}
    wanted = {s.name for s in kind.slots} | set(kind.number_names()) | ({kind.initial} - {None})
    assert own == wanted, f"{cls.__name__}'s fields are not its kind's slots, numbers and initial state"
    rule = rule_of(name)
    form = engine_form_of(rule)
    assert form is not None and form.kind is kind
    assert set(form.kfunctions) == {s.name for s in kind.slots}
    helpers = ms._helpers()
    for what in ("trigger", "flow", "reset"):
        formula = getattr(kind, what)
        assert (formula is None) == (ms._formula_name(kind, what) not in helpers)
        for arg in formula.args if formula else ():
            split = fm.split_arg(arg)
            known = arg in ("e", "y", "s") or arg in kind.number_names()
            assert known or (split is not None and split[0] in own and split[1] in ("e", "s", "y")), arg
    assert (kind.state == "none") == (kind.flow is None and kind.reset is None)
    assert rule.reads_y == kind.reads_y


def test_every_k_kind_but_the_constant_has_its_class():
    assert set(k_classes()) == set(fm.K_KINDS) - {"constant"}
    for name, cls in k_classes().items():
        assert cls.kind is fm.K_KINDS[name]
        assert [f.name for f in fields(cls)] == [n.name for n in cls.kind.numbers]
        assert f"K_{name.upper()}" in ms._helpers()


@pytest.mark.parametrize("name", list(fm.K_KINDS))
def test_every_k_kind_inverts_and_prints(name):
    kind = fm.K_KINDS[name]
    k1, k2 = (2.0, 1.5)[: len(kind.numbers)] + (0.0,) * (2 - len(kind.numbers))
    s = np.array([0.0, 0.3, 1.0, 4.0])
    r = kind.value(k1, k2, s)
    if kind.inverse is not None:
        np.testing.assert_allclose(kind.inverse(k1, k2, r), s, rtol=1e-12)
        assert np.all(np.diff(r) > 0) and r[0] == 0.0  # class K on the probe
    assert kind.text.format(**{n.name: v for n, v in zip(kind.numbers, (k1, k2), strict=False)})


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: fm.rule_kind("magic"), r"unknown rule kind 'magic'; the kinds are dynamic, static"),
        (lambda: fm.k_kind("cubic"), r"unknown K-function kind 'cubic'; the kinds are linear, quadratic"),
        (lambda: fm.k_kind(0), r"unknown K-function kind 0"),
        (lambda: fm.rule_kind(None), r"unknown rule kind None"),
        (lambda: Custom(lambda s: s).sensor_spec("gamma"), r"`gamma` is Custom"),
    ],
)
def test_an_unknown_kind_is_an_error_never_a_fallback(call, message):
    with pytest.raises(InputError, match=message):
        call()


# ---- every backend: the formulas hold at every transmission ---------------------------


#: Every rule kind, with each K-function kind in each of its slots (the shifts of :func:`rule_of`).
SHIFTED = [(n, k) for n in KINDS for k in range(len(k_classes()) if fm.RULE_KINDS[n].slots else 1)]


@pytest.mark.parametrize("backend", ["engine", "scipy"])
@pytest.mark.parametrize(("name", "shift"), SHIFTED)
def test_every_kind_sends_where_its_formula_says_on_every_backend(name, shift, backend):
    kind, rule = fm.RULE_KINDS[name], rule_of(name, shift)
    pb = ramp(rule)
    res = simulate(pb, [[X0]], T_END, z0=[0.0], backend=backend, save=SaveAt(steps=True))
    arc, ch = res.solution.arcs[0], pb.layout.channels[0]
    times = res.transmission_times(0, 0)
    assert times.size >= 3, f"{name} sends {times.size} times: the problem does not exercise it"
    for t in times:
        row = np.flatnonzero(arc.t == t)[0]  # the row before the jump, then the one after
        x, after = arc.x[row], arc.x[row + 1]
        y = float(x[0])
        e = abs(float(x[ch.held][0]) - y)
        s = float(x[ch.rule_state][0]) if kind.state != "none" else 0.0
        assert by_formula(kind, "trigger", rule, e, abs(y), s) == pytest.approx(0.0, abs=1e-7)
        assert after[ch.held][0] == pytest.approx(y, abs=1e-12)  # eq. (22): e+ = 0
        if kind.reset is not None:
            assert after[ch.rule_state][0] == pytest.approx(by_formula(kind, "reset", rule, e, abs(y), s))
    # and below zero between them: at every accepted step that is not a jump
    steps = [k for k in range(arc.t.size) if arc.t[k] not in set(times) and arc.t[k] > 0]
    for k in steps[:: max(1, len(steps) // 50)]:
        x = arc.x[k]
        e, y = abs(float(x[ch.held][0]) - float(x[0])), abs(float(x[0]))
        s = float(x[ch.rule_state][0]) if kind.state != "none" else 0.0
        assert by_formula(kind, "trigger", rule, e, y, s) < 1e-7


@pytest.mark.parametrize(("name", "shift"), SHIFTED)
def test_the_engine_and_the_reference_send_the_same_for_every_kind(name, shift):
    pb = ramp(rule_of(name, shift))
    a = simulate(pb, [[X0]], T_END, z0=[0.0], backend="engine")
    b = simulate(pb, [[X0]], T_END, z0=[0.0], backend="scipy")
    np.testing.assert_allclose(a.transmission_times(0, 0), b.transmission_times(0, 0), atol=1e-7)


# ---- the sensor node: the same formulas, sampled ------------------------------------


@pytest.mark.parametrize(("name", "shift"), SHIFTED)
def test_every_kind_runs_in_the_sensor_node_as_the_model_says(name, shift):
    kind, rule = fm.RULE_KINDS[name], rule_of(name, shift)
    T = 0.01
    node = SampledRule(rule.sensor_spec(), T)
    rng = np.random.default_rng(7)
    eta = 0.5
    fired = 0
    for k in range(300):
        e, y = float(rng.uniform(0.0, 1.5)), float(rng.uniform(-2.0, 2.0))
        before = node.eta
        fire = node.decide([e], [y])
        fired += fire
        if kind.state == "clock":  # sample k is at k T: fires at `first`, then every `period`
            first, every = round(rule.first / T), round(getattr(rule, kind.period) / T)
            assert fire == (k >= first and (k - first) % every == 0), k
            continue
        s = np.array([[before]])
        g = rule.trigger(np.zeros(1), np.array([[e]]), s, y=np.array([[y]]))[0]
        assert fire == (g >= 0.0), k
        if kind.state == "none":
            continue
        assert before == pytest.approx(eta, rel=1e-9, abs=1e-12)
        start = float(rule.reset(np.zeros(1), s)[0, 0]) if fire else before
        held = 0.0 if fire else e

        def f(t, x, held=held):
            return rule.derivative(np.zeros(1), np.array([[held]]), np.maximum(x, 0.0)[None, :])[0]

        eta = float(solve_ivp(f, (0.0, T), [start], rtol=1e-12, atol=1e-14).y[0, -1])
    assert fired > 0


@pytest.mark.parametrize(("name", "shift"), SHIFTED)
def test_every_kind_round_trips_through_the_sensor_spec(name, shift):
    rule = rule_of(name, shift)
    spec = rule.sensor_spec()
    assert spec["kind"] == name
    node = SampledRule(spec, 0.01)
    assert node.kind is fm.RULE_KINDS[name]
    assert node.numbers == {n: getattr(rule, n) for n in node.kind.number_names()}
    for slot, (k, k1, k2) in node.k.items():
        fn = getattr(rule, slot)
        assert (k, k1, k2) == ((fm.CONSTANT, fn, 0.0) if isinstance(fn, float) else fn.engine_form()[:3])
    with pytest.raises(RuleSpecError, match=r"missing key|must be"):
        SampledRule({**spec, **{n: -1.0 for n in node.kind.number_names()[:1]}}, 0.01)


@pytest.mark.parametrize("name", KINDS)
def test_every_kind_round_trips_through_the_comparison_spec(name):
    rule = rule_of(name)
    assert name in SPEC_KINDS
    table = {"name": "x", "kind": name} | {k: getattr(rule, k) for k in SPEC_KINDS[name]}
    # on a base of other numbers (and K-functions): the entry's numbers are taken
    other = rule_classes()[name](**{f.name: getattr(rule_of(name, 1), f.name) for f in fields(rule)})
    changed = {
        n.name: (0.5 if n.upper else 2.0) * getattr(other, n.name) for n in fm.RULE_KINDS[name].numbers
    }
    other = replace(other, **changed)
    made = _rule("rules[0]", table).make(0, 1, other)
    assert {k: getattr(made, k) for k in SPEC_KINDS[name]} == {k: getattr(rule, k) for k in SPEC_KINDS[name]}
    bare = {"name": "x", "kind": name}
    if fm.RULE_KINDS[name].slots:  # a kind with K-functions takes what it is not given from the base rule
        assert _rule("rules[0]", bare).make(0, 1, rule) == rule
    else:  # one without is built from the entry: the keys without a default are required
        with pytest.raises(SpecError, match=r"missing key `rules\[0\]\."):
            _rule("rules[0]", bare)


def test_a_spec_names_no_kind_that_is_not_registered():
    assert set(SPEC_KINDS) == {"base", "send_on_delta"} | set(fm.RULE_KINDS)


# ---- the docs' table of kinds ------------------------------------------------------------


def kinds_table() -> str:
    """The table of rule kinds docs/extensions.md must hold, from the registry."""
    rows = [
        "| kind (specs) | class | numbers | K-functions | state | sends when `g >= 0`, `g` = |",
        "|---|---|---|---|---|---|",
    ]
    for name, cls in rule_classes().items():
        kind = cls.kind
        g = re.search(r"``(.+?)``", kind.trigger.fn.__doc__ or "")
        assert g, f"the trigger formula of {name} says nothing in ``...``"
        slots = (
            ", ".join(f"`{s.name}`" + (" (or a number)" if s.constant else "") for s in kind.slots) or "none"
        )
        numbers = ", ".join(f"`{n}`" for n in kind.number_names())
        state = {"none": "none", "eta": "`eta` (`eta0`)", "clock": "a clock (`first`)"}[kind.state]
        if kind.reads_y:
            state += ", reads `y`"
        formula = g.group(1).replace("|", "\\|")  # a pipe in a table cell is escaped
        rows.append(f"| `{name}` | `{cls.__name__}` | {numbers} | {slots} | {state} | `{formula}` |")
    return "\n".join(rows) + "\n"


def test_the_docs_table_of_kinds_is_the_registry():
    text = DOCS.read_text()
    assert kinds_table() in text, "docs/extensions.md must hold this table of kinds:\n" + kinds_table()


@pytest.mark.parametrize(
    ("table", "base", "message"),
    [
        (
            {"kind": "periodic", "period": 0.5, "first": -1.0},
            "static",
            r"`rules\[0\]`, node 0: `first` must be >= 0; got -1",
        ),
        (
            {"kind": "static"},
            "periodic",
            r"`rules\[0\]`: kind 'static' takes `gamma` from the base rule, but node 0",
        ),
        (
            {"kind": "dynamic"},
            "generalized",
            r"kind 'dynamic' takes `alpha` from the base rule, but node 0's Gen",
        ),
    ],
)
def test_a_comparison_entry_the_base_rule_cannot_complete_names_the_entry(table, base, message):
    with pytest.raises(SpecError, match=message):
        _rule("rules[0]", {"name": "x"} | table).make(0, 1, rule_of(base))
