"""The ``etobs check`` spec format read into a certificate, for the CLI and for tuning.

A check spec names the event-triggered problem (``[system]``), where the ISS gains come
from (``[observer]``, optional) and what the certificate is asked for (``[guarantees]``);
the keys are in ``docs/specs.md``. :func:`certificate_of` reads a whole spec;
:func:`observer_gains` and :func:`certify_with` are its two halves, which
:func:`etobs.tuning.tune` calls once per observer and once per candidate.
"""

from __future__ import annotations

import contextlib
import inspect
import re
from collections.abc import Collection, Iterator
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from etobs import _validate as v
from etobs._spec import FACTORY, TABLE, SpecError
from etobs._spec import keys as _keys
from etobs._spec import number as _number
from etobs._validate import shown
from etobs.design.certificate import Certificate
from etobs.errors import InputError, InputTypeError
from etobs.estimation.problem import EstimationProblem
from etobs.examples.registry import make_problem, resolve_factory

OBSERVER_KEYS = ("structure", "A", "C", "G", "H", "slopes", "L", "P", "Q", "c_v", "c", "E_v")
GUARANTEE_KEYS = ("E", "E_estimate", "noise", "disturbance", "a_U", "d")


@dataclass(frozen=True)
class CheckOutcome:
    """What a check spec gives: the problem certified and its certificate."""

    problem: EstimationProblem
    certificate: Certificate


def check_problem(raw: dict[str, Any]) -> tuple[dict[str, Any], EstimationProblem]:
    """The checked top level of a check spec and the problem its ``[system]`` builds."""
    top = _keys("spec", raw, {"system": TABLE}, {"observer", "guarantees", "name"})
    system = _keys("system", top["system"], {"factory": FACTORY}, {"params"})
    params = system.get("params", {})
    if not isinstance(params, dict):
        raise SpecError(f"`system.params` must be a table; got {shown(params)}")
    return top, make_problem(system["factory"], params, "system.params")


def certificate_of(raw: dict[str, Any]) -> CheckOutcome:
    """The problem of a check spec (``raw``, its factory located) and its certificate."""
    top, problem = check_problem(raw)
    iss, obs_notes = None, []
    if "observer" in top:
        iss, L, obs_notes = observer_gains(top["observer"], problem)
        # the simulated problem (for E_estimate) uses the certified gain when the factory takes one
        factory, params = top["system"]["factory"], top["system"].get("params", {})
        if "L" not in params and "L" in inspect.signature(resolve_factory(factory)).parameters:
            problem = make_problem(factory, {**params, "L": L}, "system.params with observer.L")
    g = guarantees_table(top.get("guarantees", {}), iss is not None)
    cert = certify_with(problem, iss, g)
    if obs_notes:
        cert = replace(cert, notes=(*cert.notes, *obs_notes))
    return CheckOutcome(problem, cert)


def guarantees_table(table: Any, with_iss: bool) -> dict[str, Any]:
    """The ``[guarantees]`` table after checking its keys (``a_U``, ``disturbance`` need ISS gains)."""
    g = _keys("guarantees", table, set(), set(GUARANTEE_KEYS))
    unused = [k for k in ("a_U", "disturbance") if k in g]
    if not with_iss and unused:  # certify would refuse them too, naming arguments, not keys
        raise SpecError(
            f"`guarantees.{unused[0]}` needs an `[observer]` table: a_U and disturbance serve only Theorem 2 "
            "and the error bound, which rest on the observer's ISS gains; add `[observer]` or remove "
            + " and ".join(f"`guarantees.{k}`" for k in unused)
        )
    if "E_estimate" in g and "E" in g:  # one would be ignored
        raise SpecError("give either `guarantees.E` or `guarantees.E_estimate`, not both")
    return g


def rate_bound(problem: Any, g: dict[str, Any]) -> Any:
    """``E`` of the ``[guarantees]`` table ``g``: given, estimated (``E_estimate``), or ``None``."""
    if "E_estimate" in g:  # named as an estimate in the certificate
        with _table("guarantees", GUARANTEE_KEYS, others_as_they_are=True):
            return _estimate(problem, g["E_estimate"])
    if isinstance(g.get("E"), list):
        return _numbers("guarantees.E", g["E"])
    return None if "E" not in g else _number("guarantees.E", g["E"])


def certify_with(problem: Any, iss: Any, g: dict[str, Any], *, E: Any = None) -> Any:
    """The certificate of ``problem`` with the ``[guarantees]`` table ``g``.

    ``E`` (a :func:`rate_bound` computed earlier) stands for the table's ``E`` or
    ``E_estimate`` when given, so that an estimate is computed once for many candidates.
    """
    from etobs.design import certify

    with _table("guarantees", GUARANTEE_KEYS, others_as_they_are=True):
        return certify(
            problem,
            iss,
            d=_numbers("guarantees.d", g["d"]) if "d" in g else None,
            a_U=_number("guarantees.a_U", g["a_U"]) if "a_U" in g else None,
            E=rate_bound(problem, g) if E is None else E,
            noise=_numbers("guarantees.noise", g["noise"]) if "noise" in g else None,
            disturbance=_number("guarantees.disturbance", g["disturbance"]) if "disturbance" in g else None,
        )


#: The keys an ``[observer]`` table must have, with what each expects.
OBSERVER_NEEDS = {
    "L": "'design', 'paper' or a matrix",
    "c_v": "a number > 0",
    "c": "a list of numbers (one per node)",
}


def observer_table(where: str, table: Any, needs: dict[str, str] | None = None) -> dict[str, Any]:
    """An ``[observer]`` table (at key path ``where``) after checking its keys (``needs``: more required)."""
    needed = {**OBSERVER_NEEDS, **(needs or {})}
    return _keys(where, table, needed, set(OBSERVER_KEYS) - set(needed))


def observer_gains(table: Any, problem: Any) -> tuple[Any, np.ndarray, list[str]]:
    """The ISS gains of an ``[observer]`` table, its ``L``, notes on where ``P`` and ``E_v`` came from."""
    with _table("observer", OBSERVER_KEYS):
        return _iss(table, problem)


@contextlib.contextmanager
def _table(key: str, names: Collection[str], *, others_as_they_are: bool = False) -> Iterator[None]:
    """Name the spec key in an input error raised by the design functions table ``key`` feeds.

    The functions name their arguments: one named like a key of the table (``names``) is
    that key (quadratic_iss_gains's "`c` must have ..." is about `observer.c`); a message
    that already names a spec key is kept; any other gets the table's name in front, or
    is kept as it is with ``others_as_they_are`` (certify's errors about the problem).
    """
    try:
        yield
    except SpecError:
        raise
    except (InputError, InputTypeError) as exc:
        msg = str(exc)
        arg = re.match(r"`([A-Za-z_]\w*)(?=[`\[])", msg)
        if arg and arg.group(1) in names:
            raise SpecError(f"`{key}.{msg[1:]}") from exc
        if others_as_they_are:
            raise
        raise SpecError(msg if msg.startswith(f"`{key}.") else f"`{key}`: {msg}") from exc


def _iss(table: Any, problem: Any) -> tuple[Any, np.ndarray, list[str]]:
    """The ISS gains of the spec's observer, its gain ``L``, notes on where ``P`` and ``E_v`` came from."""
    from etobs.design import check_gain, observer_gain, quadratic_iss_gains, slope_vertices
    from etobs.design.iss import plant_disturbance_matrix

    obs = observer_table("observer", table)
    if "structure" in obs:
        structure = _STRUCTURES.get(obs["structure"]) if isinstance(obs["structure"], str) else None
        if structure is None:
            raise SpecError(
                f"`observer.structure` must be one of {', '.join(_STRUCTURES)}; got {shown(obs['structure'])}"
            )
        A, C, verts, paper_L = structure()
    else:
        missing = [k for k in ("A", "C") if k not in obs]
        if missing:
            raise SpecError(f"missing key `observer.{missing[0]}` (or give `observer.structure`)")
        A, C = _matrix("observer.A", obs["A"]), _matrix("observer.C", obs["C"])
        verts = ()
        if "G" in obs or "H" in obs or "slopes" in obs:
            missing = [k for k in ("G", "H", "slopes") if k not in obs]
            if missing:
                raise SpecError(f"missing key `observer.{missing[0]}` (G, H and slopes go together)")
            G, H = _matrix("observer.G", obs["G"]), _matrix("observer.H", obs["H"])
            verts = slope_vertices(G, H, v.matrix("observer.slopes", obs["slopes"], (None, 2)))
        paper_L = None
    Q = _matrix("observer.Q", obs["Q"]) if "Q" in obs else None
    if not isinstance(obs["L"], list) and obs["L"] not in ("design", "paper"):
        raise SpecError(f"`observer.L` must be 'design', 'paper' or a matrix; got {shown(obs['L'])}")
    P = _matrix("observer.P", obs["P"]) if "P" in obs else None
    notes: list[str] = []
    if obs["L"] == "design":
        if P is not None:
            raise SpecError(
                "`observer.P` goes with a given `observer.L` (a matrix or 'paper'); with L = 'design' "
                "the design finds its own P"
            )
        gain = observer_gain(A, C, verts, Q=Q)
    else:
        if obs["L"] == "paper" and paper_L is None:
            raise SpecError("`observer.L` = 'paper' needs `observer.structure` (a registered example)")
        L = paper_L if obs["L"] == "paper" else _matrix("observer.L", obs["L"])
        gain = check_gain(A, C, L, verts, P=P, Q=Q)  # with P: only re-checked, as certify's P
        if P is None:
            notes.append(
                "no observer.P given: P was found by check_gain for observer.L; the ISS gains and the "
                "error bound depend on P, so give observer.P (e.g. the ObserverGain.P of the design that "
                "gave L) to certify with that P (its bound may be smaller)"
            )
    if not gain.ok:  # the LMIs fail: no ISS gains, so bad input rather than a failed condition
        what = "`observer.L` with `observer.P`" if P is not None else "`observer.L`"
        raise SpecError(f"{what} fails the LMI re-check: {'; '.join(gain.notes) or 'vertex residuals >= 0'}")
    nodes = [list(nd.outputs) for nd in problem.nodes]
    c_v, c = _number("observer.c_v", obs["c_v"]), _numbers("observer.c", obs["c"])
    plant = problem.plant
    if "E_v" in obs:  # certify compares it with the plant's
        E_v = v.matrix("observer.E_v", obs["E_v"], (plant.n_x, plant.n_v))
    else:  # theta must be for the plant's disturbance input (x' = ... + E_v v), not the identity
        E_v = plant_disturbance_matrix(plant)
        if E_v.shape != (plant.n_x, plant.n_x) or not np.array_equal(E_v, np.eye(plant.n_x)):
            notes.append(
                f"no observer.E_v given: theta is for the plant's disturbance input E_v = {E_v.tolist()}, "
                "read from f_p (x' = ... + E_v v), not for quadratic_iss_gains' default, the identity"
            )
    return quadratic_iss_gains(gain, nodes, c_v=c_v, c=c, E_v=E_v), gain.L, notes


def _numbers(key: str, value: Any) -> list[float]:
    """A list of numbers (one per node), each checked by :func:`etobs._spec.number`."""
    if not isinstance(value, list):
        raise SpecError(f"`{key}` must be a list of numbers (one per node); got {shown(value)}")
    return [float(_number(f"{key}[{i}]", x)) for i, x in enumerate(value)]


def _matrix(key: str, value: Any) -> np.ndarray:
    """A finite matrix given as a list of rows (its shape is checked where it is used)."""
    return v.matrix(key, value, (None, None))


def _robot_arm_structure() -> tuple[Any, ...]:
    from etobs.design import slope_vertices
    from etobs.examples.robot_arm import L_PAPER, SECTOR, A, C, G

    H = np.array([[0.0, 0.0, 1.0, 0.0]])  # sigma(Hx) = 3.3 sin(x_3)
    return A, C, slope_vertices(G[:, None], H, [(-SECTOR, SECTOR)]), L_PAPER


_STRUCTURES = {"robot_arm": _robot_arm_structure}


def _estimate(problem: Any, table: Any) -> Any:
    """``E`` per node: the largest ``|dy_i/dt|`` on seeded runs from a box and its corners, times a margin."""
    from etobs.design.rates import sample_output_rate

    box = "a list of numbers (one per plant state)"
    names = ("low", "high", "runs", "t_end", "seed", "margin")
    t = _keys("guarantees.E_estimate", table, {"low": box, "high": box}, set(names[2:]))
    where = "guarantees.E_estimate"
    low, high = (v.vector(f"{where}.{k}", t[k]) for k in ("low", "high"))
    runs = int(_number(f"{where}.runs", t.get("runs", 20), lower=1, integer=True))
    t_end = _number(f"{where}.t_end", t.get("t_end", 30.0), lower=0.0, strict=True)
    margin = _number(f"{where}.margin", t.get("margin", 1.2), lower=1.0)
    seed = int(_number(f"{where}.seed", t.get("seed", 0), lower=0, integer=True))
    with _table(where, names):  # the limit on runs x t_end is checked before any run
        return sample_output_rate(problem, low, high, runs=runs, t_end=t_end, margin=margin, seed=seed)
