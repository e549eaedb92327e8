"""``tune``: the fewest transmissions for an accuracy budget, with the paper's guarantees holding.

The search is Optuna's multi-objective TPE sampler (objectives: transmissions per node
and second, simulated error; constraints: the certificate, ``tau_min``, the budget),
its study stored in SQLite in the output folder (or any database URL), so that a
killed tuning resumes with no trial lost or computed twice. Trials are asked in
batches of ``search.batch``, evaluated together on the experiment executors, then told;
a new sampler seeded by ``(search.seed, trial number)`` asks each trial, so a resumed
tuning asks what an uninterrupted one would, and both end with the same front.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import math
import socket
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from etobs._progress import progress_bar
from etobs.errors import InputError
from etobs.experiments.executors import check_execution, process_pool, usable_pool
from etobs.experiments.store import ResultStore, atomic_write
from etobs.tuning.evaluate import Evaluator
from etobs.tuning.front import pareto
from etobs.tuning.result import TrialRow, TuningResult, finish
from etobs.tuning.space import distributions, factory_kwargs, observer_of, start_values
from etobs.tuning.spec import TuneSpec, load_tune_spec

#: The worker of a tuning on its own folder's study (every unfinished trial there is its own).
LOCAL = "local"
#: Fewest first runs a candidate may be pruned on: a standard error needs a few.
MIN_PRUNE_RUNS = 5
#: The user attribute of a trial that holds its figures (one write to the storage).
ATTR = "etobs"
#: Directions of the two objectives: transmissions per node and second, error.
DIRECTIONS = ("minimize", "minimize")


def tune(
    spec: TuneSpec | str | Path,
    out: str | Path,
    *,
    trials: int | None = None,
    executor: str = "process",
    workers: int | None = None,
    scheduler: str | None = None,
    client: Any = None,
    storage: str | None = None,
    progress: bool | None = None,
    on_trial: Callable[[TrialRow], None] | None = None,
) -> TuningResult:
    """Search the triggering parameters of ``spec`` for the fewest transmissions within the budget.

    Parameters
    ----------
    spec : TuneSpec or path
        A tuning spec (:func:`~etobs.tuning.spec.load_tune_spec`; keys in docs/specs.md).
    out : path
        Output folder: the study (``study.db``), the runs (``runs/``), the tables
        (``trials``, ``front``), the front's check and sweep specs (``specs/``), the plot.
        Rerun with the same folder to resume.
    trials : int, optional
        Trials in all (default ``search.trials``); a rerun with more continues the study.
    executor, workers, scheduler, client
        Where the runs are simulated, as in :func:`~etobs.experiments.sweep.run_sweep`.
    storage : str, optional
        An Optuna storage URL (``postgresql://...``) shared by several machines, each with
        its own ``out``; default ``sqlite:///OUT/study.db``.
    progress : bool, optional
        A bar over the trials with the best point so far (default: on a terminal).
    on_trial : callable, optional
        Called with each trial's row as it is told.

    Returns
    -------
    TuningResult
        The trials, the front (validated on held-out runs) and where the outputs are.

    """
    if not isinstance(spec, TuneSpec):
        spec = load_tune_spec(spec)
    total = spec.search.trials if trials is None else trials
    if isinstance(total, bool) or not isinstance(total, int) or total < 1:
        raise InputError(f"`trials` must be a positive integer; got {trials!r}")
    check_execution(executor, workers)
    out = Path(out).resolve()  # the tables name the exported specs by absolute path
    out.mkdir(parents=True, exist_ok=True)
    store = ResultStore(out / "runs")
    with store.lock(), _execution(executor, workers, scheduler, client) as execution:
        store.clean_temporary()
        ev = Evaluator(spec, store, execution)
        study = _study(spec, out, storage, ev)
        atomic_write(out / "spec.json", json.dumps(spec.raw, indent=2, sort_keys=True, default=repr) + "\n")
        # the folder's own study is this process's alone (the lock): every trial asked and not
        # told is its own, wherever the folder is now; a shared study tells apart its machines
        worker = LOCAL if storage is None else f"{socket.gethostname()}:{out}"
        loop = _Loop(spec, ev, study, worker, on_trial)
        loop.run(total, progress)
        return finish(spec, ev, study, out)


@contextlib.contextmanager
def _execution(
    executor: str, workers: int | None, scheduler: str | None, client: Any
) -> Iterator[dict[str, Any]]:
    """The executor settings for every batch, with one process pool or Dask client for all of them."""
    if executor == "process":
        execution = {"executor": "process", "workers": workers, "pool": process_pool(workers)}
        try:
            yield execution
        finally:  # the pool in use at the end (a broken one was replaced between batches)
            execution["pool"].shutdown(wait=True, cancel_futures=True)
    elif executor == "dask" and client is None and scheduler:
        from dask.distributed import Client

        try:
            own = Client(scheduler, timeout="10s")
        except (OSError, TimeoutError, ValueError) as exc:
            raise InputError(f"cannot reach the Dask scheduler at {scheduler!r}: {exc}") from exc
        try:
            yield {"executor": "dask", "client": own}
        finally:
            own.close()
    else:
        yield {"executor": executor, "workers": workers, "scheduler": scheduler, "client": client}


def _study(spec: TuneSpec, out: Path, storage: str | None, ev: Evaluator) -> Any:
    """The Optuna study of ``spec`` (created, or loaded to resume); refused if it holds another tuning."""
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    url = storage or f"sqlite:///{(out / 'study.db').resolve()}"
    try:
        study = optuna.create_study(
            study_name=spec.name, storage=url, directions=list(DIRECTIONS), load_if_exists=True
        )
    except Exception as exc:  # a malformed URL, a driver not installed, a database that cannot be opened
        where = "`storage` (--storage)" if storage else "the study's file"
        raise InputError(f"{where} {url!r} cannot hold the study: {type(exc).__name__}: {exc}") from exc
    ident = _identity(spec)
    had = study.user_attrs.get("etobs_tuning")
    if had is None:
        study.set_user_attr("etobs_tuning", ident)
    elif had != ident:
        raise InputError(
            f"the study {spec.name!r} in {url!r} holds the trials of another tuning (other parameters, runs, "
            "budget or seed); use another output folder or `name`"
        )
    if not study.user_attrs.get("etobs_known"):  # once, also when a kill came in the middle
        _enqueue_known(spec, study, ev)
        study.set_user_attr("etobs_known", True)
    return study


def _enqueue_known(spec: TuneSpec, study: Any, ev: Evaluator) -> None:
    """Make the start design and the references inside the boxes the first trials (each once).

    The search starts from the designs the user knows (and they are on the plot and in the
    tables). A design already in the study (the same values: a reference equal to the start
    design, or one enqueued before a kill) is not enqueued again.
    """
    have = [t.params for t in study.get_trials(deepcopy=False)]
    known = [("start", {})] + [(r.name, r.params) for r in spec.references]
    for name, params in known:
        values = start_values(spec, ev.n_nodes, params)
        if values is not None and values not in have:
            study.enqueue_trial(values, user_attrs={"design": name})
            have.append(values)


def _identity(spec: TuneSpec) -> str:
    """A hash of what determines every trial's numbers (all but the number of trials)."""
    raw = {k: v for k, v in spec.raw.items() if k not in ("search", "validation", "references")}
    raw["search"] = {k: v for k, v in spec.raw.get("search", {}).items() if k != "trials"}
    return hashlib.sha256(json.dumps(raw, sort_keys=True, default=repr).encode()).hexdigest()[:20]


class _Loop:
    """Ask a batch, certify, simulate (pruning the clearly dominated), tell; until ``total`` trials."""

    def __init__(self, spec: TuneSpec, ev: Evaluator, study: Any, worker: str, on_trial: Any) -> None:
        self.spec, self.ev, self.study, self.worker, self.on_trial = spec, ev, study, worker, on_trial
        self.dists = distributions(spec, ev.n_nodes)
        self.names = [
            "certificate",
            *(["tau_min"] if spec.tau_min is not None else []),
            "budget",
            "completed",
        ]

    def run(self, total: int, progress: bool | None) -> None:
        from optuna.trial import TrialState

        done = lambda: [t for t in self.study.get_trials(deepcopy=False) if t.state.is_finished()]  # noqa: E731
        bar = progress_bar(
            total, f"tune {self.spec.name}", enabled=progress, unit="trial", initial=min(len(done()), total)
        )
        try:
            while True:
                trials = self.study.get_trials(deepcopy=False)
                batch = [t.number for t in trials if t.state == TrialState.RUNNING and self._mine(t)]
                # the next trial's number (a waiting trial, the enqueued start design, has one already)
                count = sum(t.state != TrialState.WAITING for t in trials)
                while count < total and (not batch or count % self.spec.search.batch != 0):
                    batch.append(self._ask(count))
                    count += 1
                if not batch:
                    break
                told = self._evaluate(sorted(batch))
                bar.update(told)
                best = self._best()
                if best:
                    bar.set_postfix_str(best, refresh=False)
        finally:
            bar.close()

    def _mine(self, trial: Any) -> bool:
        """Whether a trial asked and not told is this tuning's to evaluate (on a resume)."""
        if self.worker == LOCAL:
            return True
        said = trial.user_attrs.get("worker")
        # killed between ask and the worker mark: the number it was about to ask says it
        return said == self.worker or (
            said is None and self.study.user_attrs.get(self._asking) == trial.number
        )

    @property
    def _asking(self) -> str:
        return f"asking:{self.worker}"

    def _ask(self, number: int) -> int:
        import optuna

        if self.worker != LOCAL:
            self.study.set_user_attr(self._asking, number)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
            self.study.sampler = optuna.samplers.TPESampler(
                seed=_seed(self.spec.search.seed, number),
                n_startup_trials=self.spec.search.startup,
                multivariate=True,
                constant_liar=True,
            )
            trial = self.study.ask(self.dists)
        trial.set_user_attr("worker", self.worker)
        return trial.number

    def _evaluate(self, numbers: list[int]) -> int:
        import optuna
        from optuna.trial import TrialState

        spec, ev = self.spec, self.ev
        if "pool" in ev.execution:  # a worker that died broke the pool: a new one for this batch
            ev.execution["pool"] = usable_pool(ev.execution["pool"], ev.execution["workers"])
        frozen = {t.number: t for t in self.study.get_trials(deepcopy=False) if t.number in set(numbers)}
        cands = []
        for n in numbers:
            values = frozen[n].params
            obs = observer_of(spec, values)
            kwargs = factory_kwargs(spec, values, ev.n_nodes)
            cands.append((n, kwargs, obs, ev.certify(kwargs, obs)))
        live = [
            c for c in cands if not (spec.search.screen and any(x > 0 for x in c[3].constraints.values()))
        ]
        front = self._front(min(numbers))
        pruned: dict[int, Any] = {}
        first = math.ceil(spec.search.prune_share * spec.runs)
        if spec.search.prune_share > 0 and MIN_PRUNE_RUNS <= first < spec.runs and live:
            recs = ev.simulate([(c[1], c[2]) for c in live], first)
            for c, r in zip(live, recs, strict=True):
                fig = None if r is None else ev.figures(r)
                if fig is not None and _clearly_out(fig, front, spec):
                    pruned[c[0]] = fig
        full = [c for c in live if c[0] not in pruned]
        recs = ev.simulate([(c[1], c[2]) for c in full], spec.runs) if full else []
        sims = dict(zip([c[0] for c in full], recs, strict=True))
        for n, kwargs, obs, cert in cands:
            trial = optuna.trial.Trial(self.study, frozen[n]._trial_id)
            attrs: dict[str, Any] = {
                "kwargs": kwargs,
                "observer": obs,
                "cert_ok": cert.ok,
                "cert_failures": cert.failures,
                "cert_assumptions": cert.assumptions,
                "nu": _num(cert.nu),
                "mu": _num(cert.mu),
                "error_bound": _num(cert.error_bound),
                "tau": [_num(t) for t in cert.tau],
            }
            cons = dict(cert.constraints)
            if n in pruned:
                fig = pruned[n]
                attrs.update(_fig_attrs(fig), simulated="pruned")
                # its constraints on the first runs: the sampler ranks infeasible trials by how far
                # they miss, so a pruned trial must say by how much (a default 1 would say nothing)
                cons.update(ev.budget_constraint(fig))
                attrs["saved_runs"] = spec.runs - first
                state, values = TrialState.PRUNED, None
            elif n in sims and sims[n] is not None:
                fig = ev.figures(sims[n])
                cons.update(ev.budget_constraint(fig))
                attrs.update(_fig_attrs(fig), simulated="full")
                seen = _sampler_error(fig.error, spec)
                state, values = TrialState.COMPLETE, [fig.transmissions_rate, seen]
            elif n in sims:  # a chunk failed: its message is in the store's .error.json
                attrs["simulated"] = "failed"
                state, values = TrialState.FAIL, None
            else:  # screened out: the certificate rules it out whatever it simulates
                attrs["saved_runs"] = spec.runs
                attrs["simulated"] = "screened"
                state, values = TrialState.COMPLETE, [math.inf, math.inf]
            # every trial carries the same constraints; one not evaluated (a screened trial's budget)
            # is 0 for the sampler, which ranks infeasible trials by what they do miss, and blank
            # in the tables
            attrs["unevaluated"] = [k for k in self.names if k not in cons]
            for k in attrs["unevaluated"]:
                cons[k] = 0.0
            trial.set_user_attr(ATTR, attrs)  # one write: each is a transaction of the storage
            for k, x in cons.items():
                trial.set_constraint(k, float(x))
            self.study.tell(n, values, state=state)
            if self.on_trial is not None:
                self.on_trial(TrialRow.of(self.study.trials[n]))
        return len(cands)

    def _front(self, before: int) -> list[tuple[float, float]]:
        """The front of the trials numbered below ``before``, the batch's first.

        Not those of the batch: a resume that finds part of the batch told must prune as the
        uninterrupted tuning did.
        """
        trials = self.study.get_trials(deepcopy=False)
        pts = [_objectives(t) for t in trials if t.number < before and _feasible(t)]
        return [pts[i] for i in pareto(pts)]

    def _best(self) -> str:
        pts = [(*_objectives(t), t.number) for t in self.study.get_trials(deepcopy=False) if _feasible(t)]
        if not pts:
            return "no feasible point yet"
        tx, err, n = min(pts)
        return f"best: {tx:.4g} tx/node/s at error {err:.4g} (trial {n})"


def _feasible(t: Any) -> bool:
    """A completed, fully simulated trial that meets every constraint."""
    from optuna.trial import TrialState

    cons = [v for k, v in t.system_attrs.items() if k.startswith("constraints:")]
    return (
        t.state == TrialState.COMPLETE
        and t.user_attrs.get(ATTR, {}).get("simulated") == "full"
        and all(c <= 0 for c in cons)
    )


def _sampler_error(error: float, spec: TuneSpec) -> float:
    """The second objective the sampler is told: the simulated error, raised to ``error_floor x budget``.

    The search goes where the budget binds and spends no trials on errors far below it
    (``search.error_floor``). With a certified budget, whose bound is most often far above
    the simulated error, the value is then ``floor x budget`` for every candidate: the
    search minimizes transmissions alone, as the question asks. The tables and the front
    keep the true transmissions and simulated error.
    """
    return max(error, spec.search.error_floor * spec.budget.error)


def _objectives(t: Any) -> tuple[float, float]:
    """A trial's true objectives (the sampler's error may be raised to ``error_floor x budget``)."""
    a = t.user_attrs[ATTR]
    return (a["transmissions_rate"], a["error"])


def _clearly_out(fig: Any, front: list[tuple[float, float]], spec: TuneSpec) -> bool:
    """Whether a candidate's first runs show it clearly over the budget, or clearly dominated.

    Clearly: by ``search.prune_z`` standard errors of its means over those runs, so that a
    candidate is stopped early only when its remaining runs are unlikely to change the verdict.
    """
    z = spec.search.prune_z
    err, tx = fig.error - z * fig.error_se, fig.transmissions_rate - z * fig.transmissions_se
    over = spec.budget.kind == "simulated" and err > spec.budget.error
    return over or any(p[0] <= tx and p[1] <= err and p != (tx, err) for p in front)


def _seed(seed: int, number: int) -> int:
    """The sampler's seed for trial ``number``: the same on a rerun, another for every trial."""
    return int.from_bytes(hashlib.sha256(f"{seed}:{number}".encode()).digest()[:4], "little")


def _num(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _fig_attrs(fig: Any) -> dict[str, Any]:
    return {
        "runs": fig.runs,
        "completed": fig.completed,
        "transmissions_rate": _num(fig.transmissions_rate),
        "error": _num(fig.error),
        "transmissions_mean": _num(fig.transmissions_mean),
        "error_mean": _num(fig.error_mean),
        "transmissions_se": _num(fig.transmissions_se),
        "error_se": _num(fig.error_se),
        "node_rates": [_num(x) for x in fig.node_rates],
    }
