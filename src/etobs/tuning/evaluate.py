"""One candidate of a tuning: its certificate (the hard constraints) and its simulated figures.

The certificate is the one ``etobs check`` gives (:mod:`etobs.experiments.check_spec`), so
a check spec exported for a candidate certifies it with the same numbers; the
simulation is a sweep on the shared pipeline (:func:`etobs.experiments.pipeline.run_groups`)
into one chunk store, so a candidate's runs are never computed twice (a resumed tuning,
a pruned candidate's first runs, the same candidate twice).
"""

from __future__ import annotations

import inspect
import math
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from etobs._spec import SpecError
from etobs.errors import InputError
from etobs.examples.registry import make_problem, resolve_factory
from etobs.experiments.check_spec import certify_with, observer_gains, rate_bound
from etobs.experiments.pipeline import run_groups
from etobs.experiments.spec import parse_spec
from etobs.experiments.store import ResultStore, task_key
from etobs.tuning.spec import TuneSpec

#: What building a problem warns of that the certificate checks itself (Theorem 1, section 7.2).
_CERTIFIED_WARNINGS = (r".*sigma\*c = .* >= 1: Theorem 1 needs", r".*section 7\.2's condition fails")
#: Status of a run that reached its horizon (every other status stops a run early).
COMPLETED = "completed"


@dataclass(frozen=True)
class CertificateFigures:
    """What the certificate says of a candidate, and the constraints it gives (``<= 0``: met)."""

    ok: bool
    failures: str
    nu: float
    mu: float
    error_bound: float
    tau: tuple[float, ...]
    constraints: dict[str, float]
    #: The hypotheses the certificate rests on and did not check (``Certificate.assumptions``):
    #: a candidate marked certified is certified under them.
    assumptions: str = ""


@dataclass(frozen=True)
class SimulatedFigures:
    """A candidate's figures over its runs.

    ``transmissions_rate`` is the mean number of transmissions per node and second (the
    first objective), ``error`` the error statistic (the second: the mean of the per-run
    ``max |x - xhat|`` on the error window, or its quantile); ``transmissions_mean`` and
    ``error_mean`` are the per-run means as ``etobs sweep`` aggregates them.
    """

    runs: int
    completed: int
    transmissions_rate: float
    error: float
    transmissions_mean: float
    error_mean: float
    transmissions_se: float = 0.0
    error_se: float = 0.0
    node_rates: tuple[float, ...] = ()


class Evaluator:
    """Certifies and simulates the candidates of ``spec``, storing runs in ``store``."""

    def __init__(self, spec: TuneSpec, store: ResultStore, execution: dict[str, Any]) -> None:
        self.spec = spec
        self.store = store
        self.execution = execution
        needed = _required(spec)
        if needed:
            raise SpecError(
                f"the factory {spec.factory!r} needs `{needed[0]}`, which `parameters` searches: the start "
                "design is the factory called with `system.fixed` alone, so give the argument a default "
                "(the start design's value) in the factory"
            )
        start = make_problem(spec.factory, spec.fixed, "system.fixed")
        self.n_nodes = len(start.nodes)
        if isinstance(spec.tau_min, tuple) and len(spec.tau_min) != self.n_nodes:
            raise SpecError(
                f"`constraints.tau_min` must be one number or one per node ({self.n_nodes}); "
                f"got {len(spec.tau_min)}"
            )
        self.takes_L = "L" in inspect.signature(resolve_factory(spec.factory)).parameters
        # the ISS gains of each observer, computed once (an LMI design is a convex program)
        self.gains: dict[str, tuple[Any, list[list[float]], list[str]]] = {}
        for k, (name, table) in enumerate(spec.observers.items()):
            try:
                iss, L, notes = observer_gains(table, start)
            except SpecError as exc:  # the check spec's words name `observer.KEY`: say which entry
                if not name:
                    raise
                raise SpecError(str(exc).replace("`observer.", f"`observers[{k}].")) from exc
            self.gains[name] = (iss, np.asarray(L).tolist(), notes)
        first = next(iter(self.gains), None)
        problem = start if first is None else self._problem({}, first)
        # E depends on the plant alone: estimated (or read) once, for every candidate
        self.E = rate_bound(problem, spec.guarantees)
        # the start design's certificate, strictly: a mistake of `[guarantees]` (an E of the
        # wrong length, a disturbance below the problem's) is the spec's, not every candidate's
        iss = None if first is None else self.gains[first][0]
        try:
            cert = certify_with(problem, iss, spec.guarantees, E=self.E)
        except InputError as exc:
            raise SpecError(
                f"the start design (the factory with `system.fixed`) cannot be certified: {exc}"
            ) from exc
        if spec.budget.kind == "certified" and any(cert.sampled):
            raise SpecError(
                '`budget.kind` = "certified" needs Theorem 2\'s error bound, which is not proven for '
                "sampled rules (the nodes of `system` sample theirs): give the budget as "
                '`kind = "simulated"`'
            )

    def sim_kwargs(self, kwargs: dict[str, Any], observer: str | None) -> dict[str, Any]:
        """The factory's arguments a candidate is simulated with (its observer's ``L`` added).

        The observer's ``L`` is added when the factory takes ``L`` and ``system.fixed`` does not
        give it (as ``etobs check`` does); a ``system.fixed.L`` other than the observer's fails
        the certificate's condition that the ISS gains are the problem's observer.
        """
        if observer is None or not self.takes_L or "L" in self.spec.fixed:
            return dict(kwargs)
        return {**kwargs, "L": self.gains[observer][1]}

    def _problem(self, kwargs: dict[str, Any], observer: str | None) -> Any:
        # building a problem warns when sigma_i c_i >= 1 or eps_i <= gamma_i(2 m_i): the certificate
        # checks both and says so in its failures (trials.csv), once per candidate, not as a warning
        with warnings.catch_warnings():
            for said in _CERTIFIED_WARNINGS:
                warnings.filterwarnings("ignore", message=said, category=RuntimeWarning)
            return self._build(kwargs, observer)

    def _build(self, kwargs: dict[str, Any], observer: str | None) -> Any:
        return make_problem(
            self.spec.factory, {**self.spec.fixed, **self.sim_kwargs(kwargs, observer)}, "parameters"
        )

    def certify(self, kwargs: dict[str, Any], observer: str | None) -> CertificateFigures:
        """The candidate's certificate, and its constraints ``certificate``, ``tau_min``, ``budget``.

        A candidate the theorems do not cover (``certify`` refuses its problem) fails the
        ``certificate`` constraint, with the reason in ``failures``.
        """
        spec = self.spec
        iss = None if observer is None else self.gains[observer][0]
        try:
            cert = certify_with(self._problem(kwargs, observer), iss, spec.guarantees, E=self.E)
        except InputError as exc:  # not covered by the theorems: never certified
            cons = {"certificate": 1.0}
            if spec.tau_min is not None:
                cons["tau_min"] = 1.0
            if spec.budget.kind == "certified":
                cons["budget"] = 1.0
            return CertificateFigures(False, f"not covered: {exc}", math.nan, math.nan, math.nan, (), cons)
        fails = cert.failures()
        cons = {"certificate": float(len(fails))}
        taus = tuple(nd.tau for nd in cert.nodes)
        if spec.tau_min is not None:
            need = spec.tau_min if isinstance(spec.tau_min, tuple) else (spec.tau_min,) * len(taus)
            if len(need) != len(taus):
                raise InputError(
                    f"`constraints.tau_min` has {len(need)} values; the problem has {len(taus)} nodes"
                )
            cons["tau_min"] = max(_short(t, m) for t, m in zip(taus, need, strict=True))
        if spec.budget.kind == "certified":
            bound = cert.error_bound
            cons["budget"] = (bound - spec.budget.error) / spec.budget.error if math.isfinite(bound) else 1.0
        text = "; ".join(f"{c.name}{'' if c.node is None else f' [node {c.node}]'}" for c in fails)
        # sampled nodes: certified means the continuous rules' conditions, and tau (the note)
        said = [n for n in cert.notes if n.startswith("sampled rules")] if any(cert.sampled) else []
        assumed = "; ".join([*cert.assumptions, *said])
        return CertificateFigures(cert.ok, text, cert.nu, cert.mu, cert.error_bound, taus, cons, assumed)

    def simulate(
        self, candidates: list[tuple[dict[str, Any], str | None]], runs: int, seed: int | None = None
    ) -> list[list[dict[str, Any]] | None]:
        """The records of runs ``0 .. runs - 1`` of each candidate (``None``: a chunk failed).

        The candidates are one sweep (one row each) on the tuning's executor; runs already
        in the store are read back, not computed again.
        """
        rows = [self.sim_kwargs(kw, obs) for kw, obs in candidates]
        sweep = parse_spec(self.spec.sweep_raw(rows, runs=runs, seed=seed))
        run_groups(sweep, self.store, progress=False, **self.execution)
        out: list[list[dict[str, Any]] | None] = []
        for g in range(sweep.n_groups):
            recs = self.store.records(task_key(sweep, g), runs)
            out.append([recs[k] for k in range(runs)] if len(recs) == runs else None)
        return out

    def figures(self, records: list[dict[str, Any]]) -> SimulatedFigures:
        """The objectives of a candidate from its runs' records (as ``run_task`` writes them)."""
        counts = [sum(r["transmissions"]) for r in records]
        nodes = len(records[0]["transmissions"])
        errors = [r["error"] for r in records if r["error"] is not None]
        completed = sum(r["status"] == COMPLETED for r in records)
        if errors:
            stat = (
                float(np.mean(errors))
                if self.spec.quantile is None
                else float(np.quantile(errors, self.spec.quantile))
            )
            mean = float(np.mean(errors))
        else:
            stat = mean = math.inf
        return SimulatedFigures(
            runs=len(records),
            completed=completed,
            transmissions_rate=float(np.mean(counts)) / (nodes * self.spec.window)
            if self.spec.window > 0
            else math.inf,
            error=stat,
            transmissions_mean=float(np.mean(counts)),
            error_mean=mean,
            # standard errors of the means over the runs (of the rate, and of the error's mean,
            # which stands for a quantile's too), for pruning on the first runs
            transmissions_se=_se(counts) / (nodes * self.spec.window) if self.spec.window > 0 else 0.0,
            error_se=_se(errors),
            # each node's own rate: a design that silences a node shows it here
            node_rates=tuple(
                float(np.mean([r["transmissions"][i] for r in records])) / self.spec.window
                if self.spec.window > 0
                else math.inf
                for i in range(nodes)
            ),
        )

    def budget_constraint(self, fig: SimulatedFigures) -> dict[str, float]:
        """The simulated constraints: every run completed, and (simulated budget) the error within it."""
        cons = {"completed": (fig.runs - fig.completed) / fig.runs}
        if self.spec.budget.kind == "simulated":
            b = self.spec.budget.error
            cons["budget"] = (fig.error - b) / b if math.isfinite(fig.error) else 1.0
        return cons


def _required(spec: TuneSpec) -> list[str]:
    """The searched arguments the factory has no default for (the start design cannot be built)."""
    params = inspect.signature(resolve_factory(spec.factory)).parameters
    searched = {p.name for p in spec.parameters}
    return [
        k
        for k, p in params.items()
        if k in searched and k not in spec.fixed and p.default is inspect.Parameter.empty
    ]


def _se(values: list[float]) -> float:
    """Standard error of the mean of ``values`` (0 for fewer than two)."""
    return float(np.std(values, ddof=1) / math.sqrt(len(values))) if len(values) > 1 else 0.0


def _short(tau: float, need: float) -> float:
    """How far ``tau`` falls short of ``need``, relative (``<= 0``: met; an unknown ``tau`` fails)."""
    if not math.isfinite(tau):
        return 1.0
    return (need - tau) / need if need > 0 else -tau
