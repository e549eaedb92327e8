"""Specification of a rule comparison (``etobs compare SPEC``): data, validated, frozen.

A spec is a TOML file (see ``experiments/data/robot_arm_compare.toml``): every key (the
rules and their kinds, the networks), its type, default and limits, and a minimal and a
full example are in ``docs/specs.md`` ("Comparison"), which a test keeps in step with
this parser. The tables shared with a sweep spec are parsed by
:func:`etobs.experiments.common.parse_common`.
"""

from __future__ import annotations

from dataclasses import MISSING, dataclass, field, fields, replace
from functools import cached_property
from pathlib import Path
from typing import Any, TypeVar

from etobs._spec import TOP, SpecError, check_tree, renamed
from etobs._spec import keys as _keys
from etobs._spec import number as _number
from etobs._validate import shown
from etobs.errors import EtobsError
from etobs.estimation.problem import EstimationProblem
from etobs.examples.registry import located
from etobs.experiments.common import COMMON_KEYS, Experiment, check_size, normalize, parse_common
from etobs.experiments.systems import build
from etobs.hybrid.options import SolverOptions, beyond_step_limit
from etobs.model.network import (
    BernoulliLoss,
    ConstantDelay,
    Delay,
    ExponentialDelay,
    GilbertElliottLoss,
    Link,
    Loss,
    Network,
    UniformDelay,
)
from etobs.model.rules import KindRule, TriggerRule, rule_classes, send_on_delta
from etobs.model.sampled import Sampled

_T = TypeVar("_T")

#: The rule classes of etobs by kind name: each a kind of :data:`etobs.formulas.RULE_KINDS`.
RULE_CLASSES: dict[str, type[KindRule]] = rule_classes()


def _kind_keys(cls: type[KindRule]) -> tuple[str, ...]:
    """The keys a spec may give for a rule kind: its numbers and its initial state."""
    kind = cls.kind
    return kind.number_names() + ((kind.initial,) if kind.initial else ())


def _carries(cls: type[KindRule]) -> bool:
    """Whether a rule of ``cls`` built from a spec entry takes what it is not given from the base rule.

    A kind with K-functions takes them from the base rule, and its numbers with them; a
    kind without is built from the entry alone.
    """
    return bool(cls.kind.slots)


def _required(kind: str) -> tuple[str, ...]:
    """The keys an entry of ``kind`` must give: those it can take from nowhere else."""
    if kind == "send_on_delta":
        return ("delta",)
    cls = RULE_CLASSES.get(kind)
    if cls is None or _carries(cls):
        return ()
    own = {f.name for f in fields(cls) if f.default is MISSING and f.default_factory is MISSING}
    return tuple(k for k in RULE_KINDS[kind] if k in own)


#: Keys of each rule kind (besides ``name``, ``kind`` and ``observer_copy``): ``base``, the
#: kinds of :data:`etobs.formulas.RULE_KINDS` and the preset ``send_on_delta``.
RULE_KINDS: dict[str, tuple[str, ...]] = {
    "base": (),
    **{name: _kind_keys(cls) for name, cls in RULE_CLASSES.items()},
    "send_on_delta": ("delta",),
}

#: Keys of every rule entry that run its rule sampled (:class:`~etobs.model.Sampled`): the
#: period and the phase of its samples, a number or one per node.
SAMPLE_KEYS = ("sample_period", "sample_phase")

#: What an entry's name and a rule's number expect, in a missing key's error.
_NAME = "a non-empty string"
_PER_NODE = "a number (every node) or a list of numbers (one per node)"


@dataclass(frozen=True)
class RuleEntry:
    """One rule of the comparison, applied to every output node."""

    name: str
    kind: str
    params: dict[str, Any]
    observer_copy: bool = False
    #: Its key path in errors, by position as every parser error writes it (``rules[3]``).
    where: str = field(default="rules[]", compare=False)

    def value(self, key: str, node: int, n_nodes: int) -> float:
        """The parameter ``key`` of ``node``: a number for all nodes, or one per node."""
        raw = self.params[key]
        where = f"{self.where}.{key}"
        if isinstance(raw, list):
            if len(raw) != n_nodes:
                raise SpecError(f"`{where}` has {len(raw)} values but the problem has {n_nodes} nodes")
            raw = raw[node]
            where = f"{where}[{node}]"
        return float(_number(where, raw))

    def make(self, node: int, n_nodes: int, base: TriggerRule) -> TriggerRule:
        """The rule of this entry for ``node``, whose base rule is ``base``.

        A kind with K-functions takes them from the base rule, which must have each of them
        (``static`` takes ``gamma``), and with them every number the entry does not give
        (so it means the same: ``eps`` of ``static`` on a dynamic base); a base rule of the
        kind's own class or a subclass of it (a rule of your own) is changed only in the
        keys given. A kind without K-functions is built from the entry and its defaults.
        """
        p = {k: self.value(k, node, n_nodes) for k in self.params}
        sample = {k: p.pop(k) for k in SAMPLE_KEYS if k in p}
        try:
            rule = self._made(node, p, base)
            if not sample:
                return rule
            try:
                return Sampled(rule, period=sample["sample_period"], phase=sample.get("sample_phase", 0.0))
            except EtobsError as exc:  # said in the spec's words
                said = str(exc).replace("`period`", "`sample_period`").replace("`phase`", "`sample_phase`")
                raise SpecError(f"`{self.where}`, node {node}: {said}") from exc
        except SpecError:
            raise
        except EtobsError as exc:
            raise SpecError(f"`{self.where}`, node {node}: {exc}") from exc

    def _made(self, node: int, p: dict[str, float], base: TriggerRule) -> TriggerRule:
        """The entry's rule for ``node`` from its numbers ``p`` (:meth:`make`), before sampling."""
        if self.kind == "base":
            return base
        if self.kind == "send_on_delta":
            return send_on_delta(p["delta"])
        cls = RULE_CLASSES[self.kind]
        if isinstance(base, cls):
            return replace(base, **p)
        lacking = [slot.name for slot in cls.kind.slots if not hasattr(base, slot.name)]
        if lacking:
            raise SpecError(
                f"`{self.where}`: kind {self.kind!r} takes `{'`, `'.join(lacking)}` from the base rule, "
                f"but node {node}'s {type(base).__name__} has none"
            )
        args: dict[str, Any] = {}
        for f in fields(cls):
            if f.name in p:
                args[f.name] = p[f.name]
            elif hasattr(base, f.name) and _carries(cls):
                args[f.name] = getattr(base, f.name)
        return cls(**args)  # the keys without a default are required by the parser

    def apply(self, base: EstimationProblem, network: Network | None) -> EstimationProblem:
        """The base problem with this rule on every output node, and ``network``."""
        n = base.n_nodes
        nodes = tuple(replace(nd, rule=self.make(i, n, nd.rule)) for i, nd in enumerate(base.nodes))
        hold = "innovation" if self.observer_copy else base.hold
        return replace(base, nodes=nodes, hold=hold, network=network)


@dataclass(frozen=True)
class NetworkEntry:
    """One network setting of the comparison; ``network`` is ``None`` for the ideal one."""

    name: str
    network: Network | None


#: Why an entry is not run: the observer copy needs the ideal network.
COPY_NEEDS_IDEAL = (
    "the observer copy of Remark 3 is simulated as a perfect copy, which a lossy or delayed network "
    "would break (each node's copy would drift from the observer)"
)


@dataclass(frozen=True, kw_only=True)
class CompareSpec(Experiment):
    """A validated comparison; build it with :func:`parse_compare_spec`.

    Its groups are the entries: every rule on every network (networks outer), except
    the pairs listed in :attr:`skipped`.
    """

    params: dict[str, Any]
    rules: tuple[RuleEntry, ...]
    networks: tuple[NetworkEntry, ...]

    @classmethod
    def from_raw(cls, raw: dict[str, Any]) -> CompareSpec:
        """Validate a spec given as a dictionary (:func:`parse_compare_spec`)."""
        return parse_compare_spec(raw)

    @cached_property
    def _pairs(self) -> tuple[tuple[RuleEntry, NetworkEntry, str], ...]:
        """Every (rule, network) pair, networks outer, with why it does not run (or ``""``)."""
        return tuple((r, n, _why_not(r, n)) for n in self.networks for r in self.rules)

    @property
    def entries(self) -> tuple[tuple[RuleEntry, NetworkEntry], ...]:
        """The (rule, network) pairs that run, in the order of the table."""
        return tuple((r, n) for r, n, why in self._pairs if not why)

    @property
    def skipped(self) -> tuple[tuple[str, str, str], ...]:
        """``(rule, network, why)`` of every pair that does not run."""
        return tuple((r.name, n.name, why) for r, n, why in self._pairs if why)

    @property
    def n_groups(self) -> int:
        """Number of entries that run."""
        return len(self.entries)

    def group_identity(self, group: int) -> Any:
        """The factory's arguments, the rule's kind and numbers and the network (not the names)."""
        rule, network = self.entries[group]
        return normalize(
            {
                "params": self.params,
                "rule": [rule.kind, rule.params, rule.observer_copy],
                "network": repr(network.network),
            }
        )

    def where(self, group: int) -> str:
        """``rule 'R' on network 'N'``."""
        rule, network = self.entries[group]
        return f"rule {rule.name!r} on network {network.name!r}"

    def base(self) -> EstimationProblem:
        """The factory's problem, on which every rule is applied."""
        return build(self.factory, self.params, len(self.initial_states.low), "system.params")

    def problem(self, group: int) -> EstimationProblem:
        """The base problem with the entry's rule on every output node and its network."""
        rule, network = self.entries[group]
        problem = rule.apply(self.base(), network.network)
        self.initial_states.check_z0(problem.observer.n_z)
        return problem

    def check(self) -> None:
        """Build every entry's problem: a wrong parameter or `initial_states.z0` fails before any run."""
        base = self.base()
        for rule, network in self.entries:
            self.initial_states.check_z0(rule.apply(base, network.network).observer.n_z)

    def resolved(self) -> dict[str, Any]:
        """The common settings, the factory's arguments, the rules and the networks."""
        rules = [
            {"name": r.name, "kind": r.kind, **r.params, "observer_copy": r.observer_copy} for r in self.rules
        ]
        networks = [{"name": n.name, "network": repr(n.network)} for n in self.networks]
        return {**super().resolved(), "params": self.params, "rules": rules, "networks": networks}


def _why_not(rule: RuleEntry, network: NetworkEntry) -> str:
    """Why ``rule`` does not run on ``network`` (``""``: it runs)."""
    return COPY_NEEDS_IDEAL if rule.observer_copy and network.network is not None else ""


def parse_compare_spec(raw: dict[str, Any], *, folder: str | Path | None = None) -> CompareSpec:
    """Validate a comparison spec given as a dictionary (the parsed TOML).

    A relative ``path/file.py`` factory is taken from ``folder`` (the spec file's; made
    absolute in the spec's ``raw``, which its workers read), or from the current folder
    when it is called if ``folder`` is ``None``.
    """
    check_tree(raw)
    raw = located(raw, folder)
    required, optional = COMMON_KEYS
    rules = "a non-empty array of tables ([[rules]])"
    top = _keys(TOP, raw, {**required, "rules": rules}, optional | {"networks"})
    common = parse_common(top, default_name="compare", kwargs_key="params")
    params = common.pop("kwargs")
    # refused before any run is spent: each would stop at its step limit
    too_long = beyond_step_limit(
        common["t_end"], SolverOptions(**common["solver"]), t_end="horizon.t_end", solver="solver."
    )
    if too_long:
        raise SpecError(too_long)
    rules = _list("rules", top["rules"], _rule)
    networks = _list("networks", top.get("networks", [{"name": "ideal"}]), _network)
    check_size(len(rules) * len(networks), common["initial_states"].runs, "`rules` x `networks`")
    return CompareSpec(**common, params=params, rules=rules, networks=networks, raw=raw)


def _list(key: str, items: Any, parse: Any) -> tuple[Any, ...]:
    if not isinstance(items, list) or not items:
        raise SpecError(f"`{key}` must be a non-empty array of tables ([[{key}]]); got {shown(items)}")
    out = tuple(parse(f"{key}[{i}]", item) for i, item in enumerate(items))
    names = [e.name for e in out]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise SpecError(f"`{key}` names must be distinct; {twice[0]!r} is used twice")
    return out


def _entry_name(where: str, table: dict[str, Any]) -> str:
    name = table.get("name")
    if not isinstance(name, str) or not name:
        raise SpecError(f"`{where}.name` must be a non-empty string; got {shown(name)}")
    return name


def _rule(where: str, table: Any) -> RuleEntry:
    if not isinstance(table, dict):
        raise SpecError(f"`{where}` must be a table; got {type(table).__name__}")
    kind = table.get("kind")
    if not isinstance(kind, str) or kind not in RULE_KINDS:
        raise SpecError(f"`{where}.kind` must be one of {', '.join(RULE_KINDS)}; got {shown(kind)}")
    required = {"name": _NAME, "kind": "a rule kind"} | {k: _PER_NODE for k in _required(kind)}
    t = _keys(where, table, required, set(RULE_KINDS[kind]) | {"observer_copy", *SAMPLE_KEYS})
    if "sample_phase" in t and "sample_period" not in t:
        raise SpecError(
            f"`{where}.sample_phase` needs `{where}.sample_period` (the rule is continuous without it)"
        )
    copy = t.get("observer_copy", False)
    if not isinstance(copy, bool):
        raise SpecError(f"`{where}.observer_copy` must be true or false; got {shown(copy)}")
    params = {k: v for k, v in t.items() if k not in ("name", "kind", "observer_copy")}
    for k, val in params.items():
        for i, x in enumerate(val if isinstance(val, list) else [val]):
            _number(f"{where}.{k}" + (f"[{i}]" if isinstance(val, list) else ""), x)
    return RuleEntry(name=_entry_name(where, t), kind=kind, params=params, observer_copy=copy, where=where)


def _network(where: str, table: Any) -> NetworkEntry:
    t = _keys(where, table, {"name": _NAME}, {"delay", "loss", "capacity", "seed"})
    name = _entry_name(where, t)
    if set(t) == {"name"}:
        return NetworkEntry(name, None)
    try:
        link = Link(
            delay=_delay(f"{where}.delay", t.get("delay", 0.0)),
            loss=_loss(f"{where}.loss", t.get("loss")),
            capacity=int(_number(f"{where}.capacity", t.get("capacity", 16), lower=1, integer=True)),
        )
    except SpecError:
        raise
    except EtobsError as exc:
        raise SpecError(f"`{where}`: {exc}") from exc
    seed = int(_number(f"{where}.seed", t.get("seed", 0), lower=0, integer=True))
    return NetworkEntry(name, Network(link, seed=seed))


def _delay(where: str, value: Any) -> Delay:
    if not isinstance(value, dict):
        return _made(ConstantDelay, where, {"d": (float(_number(where, value)), where)})
    t = _keys(where, value, set(), {"uniform", "exponential"})
    if len(t) != 1:
        raise SpecError(f"`{where}` must give exactly one of uniform = [lo, hi], exponential = [scale, min]")
    ((kind, args),) = t.items()
    nums = _numbers(f"{where}.{kind}", args, 2)
    cls, names = (
        (UniformDelay, ("low", "high")) if kind == "uniform" else (ExponentialDelay, ("scale", "minimum"))
    )
    return _made(
        cls, where, {n: (x, f"{where}.{kind}[{i}]") for i, (n, x) in enumerate(zip(names, nums, strict=True))}
    )


def _loss(where: str, value: Any) -> float | Loss | None:
    if value is None:
        return None
    if not isinstance(value, dict):
        return _made(BernoulliLoss, where, {"p": (float(_number(where, value)), where)})
    t = _keys(
        where, value, {"gilbert_elliott": "a list of 4 numbers [p_gb, p_bg, loss_good, loss_bad]"}, set()
    )
    nums = _numbers(f"{where}.gilbert_elliott", t["gilbert_elliott"], 4)
    names = ("p_gb", "p_bg", "loss_good", "loss_bad")
    return _made(
        GilbertElliottLoss,
        where,
        {n: (x, f"{where}.gilbert_elliott[{i}]") for i, (n, x) in enumerate(zip(names, nums, strict=True))},
    )


def _made(cls: type[_T], where: str, args: dict[str, tuple[float, str]]) -> _T:
    """``cls(**{argument: value})`` for ``args = {argument: (value, spec key)}``.

    The class checks its arguments (one implementation of each limit); its error names
    the spec key the value came from (`` `networks[1].loss` must be <= 1``), not the
    class's argument (`` `p` ``).
    """
    try:
        return cls(**{n: x for n, (x, _) in args.items()})
    except EtobsError as exc:
        raise renamed(exc, {n: key for n, (_, key) in args.items()}, where) from exc


def _numbers(where: str, value: Any, n: int) -> list[float]:
    if not isinstance(value, list) or len(value) != n:
        raise SpecError(f"`{where}` must be a list of {n} numbers; got {shown(value)}")
    return [float(_number(f"{where}[{i}]", x)) for i, x in enumerate(value)]
