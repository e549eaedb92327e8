"""``etobs tune SPEC``: the fewest transmissions for an accuracy budget, with the guarantees holding."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from etobs.cli._args import folder, load_toml, positive_int
from etobs.examples.registry import located

PACKAGED = {"robot_arm": "robot_arm_tune.toml"}


def add_parser(sub: Any) -> None:
    """Register ``etobs tune``."""
    from etobs.experiments.executors import EXECUTORS

    p = sub.add_parser(
        "tune",
        help="search the triggering parameters: fewest transmissions within an error budget, certified",
        description="Run or resume a tuning (rerunning with the same --out resumes it).",
    )
    p.add_argument(
        "spec", metavar="SPEC", help=f"tuning spec (TOML), or a packaged one: {', '.join(PACKAGED)}"
    )
    p.add_argument("--out", type=folder, default=None, help="output folder (default: tune-NAME)")
    p.add_argument(
        "--trials", type=positive_int, default=None, help="trials in all (overrides search.trials)"
    )
    p.add_argument(
        "--executor", choices=EXECUTORS, default=None, help="where runs are simulated (default: process)"
    )
    p.add_argument("--workers", type=positive_int, default=None, help="local processes (default: cores)")
    p.add_argument("--scheduler", default=None, help="Dask scheduler address, e.g. tcp://10.0.0.5:8786")
    p.add_argument(
        "--storage",
        default=None,
        help="Optuna storage URL shared by several machines (default: sqlite in OUT/study.db)",
    )
    p.add_argument("--no-plot", action="store_true", help="do not draw OUT/front.png")
    p.add_argument(
        "--progress",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="progress bar over trials with the best point so far (default: when stderr is a terminal)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Tune, write the tables, specs and plot, print the front; 1 when no point meets the budget."""
    from etobs.errors import InputError
    from etobs.tuning import parse_tune_spec, tune

    base = None if args.spec in PACKAGED else Path(args.spec).resolve().parent
    raw = load_toml(args.spec, PACKAGED, "etobs.tuning")
    spec = parse_tune_spec(located(raw, base), folder=base)
    executor = args.executor or ("dask" if args.scheduler else "process")
    if args.scheduler and executor != "dask":
        raise InputError(f"--scheduler needs --executor dask; got --executor {executor}")
    out = args.out or Path(f"tune-{spec.name}")
    result = tune(
        spec,
        out,
        trials=args.trials,
        executor=executor,
        workers=args.workers,
        scheduler=args.scheduler,
        storage=args.storage,
        progress=args.progress,
    )
    if not args.no_plot:
        _plot(result)
    print(report(result))
    if not result.front:  # one line on stderr, as every failed command says it
        print(f"etobs: {no_front(result)}", file=sys.stderr)
        return 1
    return 0


def no_front(result: Any) -> str:
    """Why no point is on the front, in one line: the certified candidate nearest, and what it missed."""
    head = f"no candidate of {len(result.trials)} met every constraint"
    certified = [r for r in result.trials if r["certified"]]
    if not certified:
        return f"{head}: none was certified (see cert_failures in trials.csv)"

    def missed(r: dict[str, Any]) -> dict[str, float]:
        cons = {k[len("constraint_") :]: v for k, v in r.items() if k.startswith("constraint_")}
        return {k: v for k, v in cons.items() if v is not None and v > 0}

    near = min(certified, key=lambda r: (sum(missed(r).values()), r["trial"]))
    what = []
    for k in missed(near):
        if k == "budget" and result.budget_kind == "certified":
            what.append(
                f"its certified bound {near['error_bound']:.4g} is over the budget {result.budget:.4g}"
            )
        elif k == "budget":
            runs = " on its first runs (pruned)" if near["evaluated"] == "pruned" else ""
            what.append(f"its error{runs} {near['error']:.4g} is over the budget {result.budget:.4g}")
        elif k == "tau_min":
            taus = ", ".join(
                f"{v:.4g}" for kk, v in near.items() if kk.startswith("tau_node") and v is not None
            )
            what.append(f"its tau_i ({taus} s) fall short of constraints.tau_min")
        else:
            what.append(f"{near['runs'] - near['completed']} of its runs stopped early")
    return (
        f"{head}: the certified candidate nearest, trial {near['trial']}: {'; '.join(what) or 'see its row'} "
        "(a constraint_* column above 0 in trials.csv is one a trial misses: widen the boxes, add "
        "trials or ease that constraint)"
    )


def report(result: Any) -> str:
    """The front and the references as text (also in ``OUT/tuning.json``)."""
    lines = [
        f"{len(result.trials)} trials, {sum(r['feasible'] for r in result.trials)} feasible, "
        f"{len(result.front)} on the front; {result.saved_runs} runs not simulated (screened or pruned); "
        f"results in {result.out}/",
        f"budget ({result.budget_kind}): {result.budget:.6g}",
        "front (transmissions per node and second, error; then on held-out runs):",
    ]
    for k, r in enumerate(result.front):
        flag = "  HELD-OUT ERROR OVER BUDGET" if r["holdout_over_budget"] else ""
        bound = "" if r.get("error_bound") is None else f", certified bound {r['error_bound']:.4g}"
        lines.append(
            f"  {k:2d}. trial {r['trial']}: {r['transmissions_rate']:.4g} tx/node/s, error {r['error']:.4g}"
            f"{bound}; held out {_fmt(r['holdout_transmissions_rate'])} tx/node/s, error "
            f"{_fmt(r['holdout_error'])}{flag}"
        )
    if not result.front:
        lines.append("  none: no candidate met every constraint (see trials.csv, constraint_* <= 0 is met)")
    for r in result.references:
        lines.append(
            f"reference {r['name']!r}: {_fmt(r['transmissions_rate'])} tx/node/s, error {_fmt(r['error'])}; "
            f"held out {_fmt(r['holdout_transmissions_rate'])}, {_fmt(r['holdout_error'])}"
            f"{'' if r['certified'] else ' (not certified)'}"
        )
    return "\n".join(lines)


def _fmt(x: Any) -> str:
    return "n/a" if x is None else f"{x:.4g}"


def _plot(result: Any) -> None:
    try:
        from etobs.plot import plot_front

        fig, _ = plot_front(result)
    except ImportError:  # the plot extra is not installed: the tables are written all the same
        print("note: matplotlib is not installed (pip install 'etobs[plot]'): no front.png")
        return
    fig.savefig(result.out / "front.png", dpi=130)
