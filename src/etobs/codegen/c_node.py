"""One sensor node as a self-contained C99 module: :func:`generate_node`, :func:`write_node`.

The module runs the node's sampled rule (:mod:`etobs.runtime.sampled_rule`), encodes and
authenticates its packets in the wire format the observer service accepts
(:mod:`etobs.runtime.packet`, HMAC-SHA256 in ``etobs_sha256.c``, self-contained) and
keeps its sequence numbers as :class:`etobs.runtime.sensor.SequenceStore` does, through
callbacks the firmware provides (radio send, flash write, clock, sensor read). No
``malloc``; its state is one fixed-size struct.

The rule is written from its kind's descriptor (:mod:`etobs.formulas`): each formula's
expression translated to C (:mod:`etobs.codegen.c_expr`), the steps of a sample those of
:func:`etobs.formulas.sample_decision`, the filter's period that of
:func:`etobs.formulas.eta_period` (a linear decay with ``exp(-a T)`` computed here, in
Python, and written as a constant: the C needs no ``exp``). The ``float64`` profile
computes what the Python sensor node computes, bit for bit (the conformance vectors,
:mod:`etobs.codegen.vectors`, check it); ``float32`` computes the rule in single
precision for FPUs such as the Cortex-M4F's.
"""

from __future__ import annotations

import importlib.resources
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from etobs import formulas as fm
from etobs._version import __version__
from etobs.codegen.c_expr import PROFILES, c_expression, literal
from etobs.errors import InputError
from etobs.runtime.packet import MAX_VALUES
from etobs.runtime.sampled_rule import RuleSpecError, SampledRule

#: The files every generated folder has besides the node's own two.
STATIC_FILES = ("etobs_sha256.c", "etobs_sha256.h", "LICENSE", "main.c", "etobs_vectors.c", "etobs_host.c")


@dataclass(frozen=True)
class NodeModule:
    """A generated node: its files by name, and what it was generated for."""

    files: dict[str, str]
    node: int
    n_values: int
    period: float
    profile: str
    kind: str


def _read(name: str) -> str:
    return importlib.resources.files("etobs.codegen").joinpath("c", name).read_text(encoding="utf-8")


def generate_node(
    spec: Mapping[str, Any],
    period: float,
    *,
    node: int,
    n_values: int,
    profile: str = "float64",
    name: str = "",
) -> NodeModule:
    """The C module of node ``node`` running the rule ``spec`` at ``period``.

    Parameters
    ----------
    spec : mapping
        The rule as a sensor node takes it (:meth:`~etobs.model.rules.TriggerRule.sensor_spec`).
    period : float
        Sampling period ``T > 0``, seconds.
    node : int
        The node's id (``0 .. 65535``), written into its packets.
    n_values : int
        How many outputs it measures and sends (``1 .. 64``).
    profile : {"float64", "float32"}
        The precision of the rule's arithmetic (samples and packets are always ``double``).
    name : str
        The spec's name, for the files' header comments.

    Raises
    ------
    InputError
        A rule or K-function the generator cannot write (one line naming it), a bad
        argument.

    """
    if profile not in PROFILES:
        raise InputError(f"`profile` must be one of {', '.join(PROFILES)}; got {profile!r}")
    if isinstance(node, bool) or not isinstance(node, int) or not 0 <= node < 2**16:
        raise InputError(f"`node` must be an integer in 0..65535; got {node!r}")
    if isinstance(n_values, bool) or not isinstance(n_values, int) or not 1 <= n_values <= MAX_VALUES:
        raise InputError(f"`n_values` must be an integer in 1..{MAX_VALUES}; got {n_values!r}")
    try:
        rule = SampledRule(spec, period)
    except RuleSpecError as exc:
        raise InputError(f"etobs codegen c: {exc}") from None
    prof = PROFILES[profile]
    kind = rule.kind
    if kind.state == "clock" and not (abs(rule.count) < 2**62 and rule.every < 2**62):
        raise InputError(
            f"etobs codegen c: a periodic rule of {rule.every!r} samples a period, first at sample "
            f"{rule.every - rule.count - 1!r}, does not fit the C node's 64-bit sample count"
        )
    uses_pow = any(k[0] is fm.POWER for k in rule.k.values())
    libm = f"{prof['sqrt']}" + (f", {prof['pow']}" if uses_pow else "")
    subs = {
        "@NODE@": str(node),
        "@N@": str(n_values),
        "@SPEC@": name or "a rule spec",
        "@KIND@": kind.name,
        "@PERIOD@": f"{rule.period:g}",
        "@PERIOD_LITERAL@": literal(rule.period, "float64"),
        "@PROFILE@": profile,
        "@REAL@": prof["real"],
        "@VERSION@": __version__,
        "@LIBM@": libm,
        "@STATE_BYTES@": "about " + str(_state_bytes(n_values, profile)),
        "@RULE@": _rule_source(rule, profile),
    }
    files = {}
    for out, template in (("etobs_node.h", "etobs_node.h.in"), ("etobs_node.c", "etobs_node.c.in")):
        text = _read(template)
        for key, value in subs.items():
            text = text.replace(key, value)
        files[out] = text
    for static in STATIC_FILES:
        files[static] = _read(static)
    files["README.md"] = _readme(subs, rule, n_values)
    return NodeModule(files, node, n_values, rule.period, profile, kind.name)


def write_node(module: NodeModule, out: str | Path) -> list[Path]:
    """Write the module's files into the folder ``out`` (created); the paths written."""
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for name, text in sorted(module.files.items()):
        path = folder / name
        path.write_text(text, encoding="utf-8")
        written.append(path)
    return written


def _state_bytes(n_values: int, profile: str) -> int:
    """The node struct's size on a 32-bit MCU (pointers of 4 bytes, doubles aligned to 8)."""
    real = 8 if profile == "float64" else 4
    io = 5 * 4
    size = io + 32  # io, key
    size = (size + 7) // 8 * 8 + 8 + 8 * n_values  # session, sent
    size += (
        real + (8 - real % 8) % 8 + 8 + 4 + 4 + 8 + 8 + 8 + 4 + real
    )  # eta, count, started, seq, k, counts
    return (size + 7) // 8 * 8


def _rule_source(rule: SampledRule, profile: str) -> str:
    """The C of the rule: its K-functions, formulas, filter period and ``decide`` (module docstring)."""
    prof, kind = PROFILES[profile], rule.kind
    real = "etobs_real"
    lit = _literal(profile)
    lines = [
        f"#define SQRT {prof['sqrt']}",
        f"#define READS_Y {int(kind.reads_y)}",
        f"#define ETA0 {lit(rule.eta)}",
    ]
    count0 = rule.count if kind.state == "clock" else 0
    lines.append(f"#define COUNT0 ((int64_t){count0})")

    def k_expr(slot: str, at: str) -> str:
        kk, k1, k2 = rule.k[slot]
        return c_expression(kk.value, [lit(k1), lit(k2), at], profile)

    def formula(f: fm.Formula, e: str, y: str, s: str) -> str:
        given = {"e": e, "y": y, "s": s}
        args = []
        for what, a, at in f.plan:
            if what == 0:
                args.append(given[("e", "y", "s")[int(a)]])
            elif what == 1:
                args.append(lit(rule.numbers[str(a)]))
            else:
                args.append(k_expr(str(a), given[("e", "y", "s")[at]]))
        return c_expression(f.fn, args, profile)

    if kind.state == "clock":  # as SampledRule.decide: count samples, fire every `every`
        lines += [
            f"#define EVERY ((int64_t){rule.every})",
            f"static int decide(etobs_node *n, {real} e, {real} ym) {{",
            "    (void)e;",
            "    (void)ym;",
            "    n->count += 1;",
            "    n->trigger = (etobs_real)(n->count - EVERY);",
            "    if (n->count >= EVERY) {",
            "        n->count = 0;",
            "        return 1;",
            "    }",
            "    return 0;",
            "}",
        ]
        return "\n".join(lines)
    body = [
        f"static int decide(etobs_node *n, {real} e, {real} ym) {{",
        f"    {real} s = n->eta;",
        f"    {real} g = {formula(kind.trigger, 'e', 'ym', 's')}; /* eq. (15) at the sample */",
        "    int fire = g >= 0;",
        "    (void)ym;",
        "    n->trigger = g;",
    ]
    if kind.state == "eta":
        assert kind.reset is not None and kind.flow is not None and kind.decay is not None
        lines += _eta_period(rule, profile)
        body += [
            "    if (fire) {",
            f"        s = {formula(kind.reset, 'e', 'ym', 's')}; /* eq. (14), at the transmission */",
            "        e = 0;",
            "    }",
            f"    n->eta = eta_period(s, {formula(kind.flow, 'e', 'ym', lit(0.0))});",
        ]
    else:
        body.append("    (void)s;")
    body += ["    return fire;", "}"]
    return "\n".join(lines + body)


def _literal(profile: str) -> Any:
    def lit(x: float) -> str:
        return literal(x, profile)

    return lit


def _eta_period(rule: SampledRule, profile: str) -> list[str]:
    """``eta_period`` of :func:`etobs.formulas.eta_period` for the rule's decay, in C."""
    kk, k1, k2 = rule.k[rule.kind.decay or ""]
    lit = _literal(profile)
    real = "etobs_real"
    T = rule.period
    if kk is fm.LINEAR:  # exact: exp(-a T) computed here, as eta_exact computes it
        import math

        d = math.exp(-k1 * T)
        return [
            f"/* eta' = drive - {k1!r} eta over T = {T!r}: exact (exp(-a T) = {d!r}) */",
            f"static {real} eta_period({real} eta, {real} drive) {{",
            f"    return {lit(d)} * eta + drive * {lit(1.0 - d)} / {lit(k1)};",
            "}",
        ]
    K = c_expression(kk.value, [lit(k1), lit(k2), "c"], profile)
    h = T / fm.ETA_SUBSTEPS
    return [
        f"/* eta' = drive - K(max(eta, 0)) over T = {T!r}: {fm.ETA_SUBSTEPS} Runge-Kutta substeps */",
        f"static {real} eta_rate({real} s, {real} drive) {{",
        f"    {real} c = ({lit(0.0)} > s) ? {lit(0.0)} : s; /* Python's max(s, 0.0) */",
        f"    return drive - {K};",
        "}",
        f"static {real} eta_period({real} eta, {real} drive) {{",
        f"    const {real} h = {lit(h)};",
        f"    {real} k1, k2, k3, k4;",
        "    int k;",
        f"    for (k = 0; k < {fm.ETA_SUBSTEPS}; k++) {{",
        "        k1 = eta_rate(eta, drive);",
        f"        k2 = eta_rate(eta + h / {lit(2.0)} * k1, drive);",
        f"        k3 = eta_rate(eta + h / {lit(2.0)} * k2, drive);",
        "        k4 = eta_rate(eta + h * k3, drive);",
        f"        eta = eta + h / {lit(6.0)} * (k1 + {lit(2.0)} * k2 + {lit(2.0)} * k3 + k4);",
        "    }",
        f"    return ({lit(0.0)} > eta) ? {lit(0.0)} : eta; /* max(eta, 0.0) */",
        "}",
    ]


def _readme(subs: dict[str, str], rule: SampledRule, n_values: int) -> str:
    text = _read("README.md.in")
    for key, value in subs.items():
        text = text.replace(key, value)
    return text
