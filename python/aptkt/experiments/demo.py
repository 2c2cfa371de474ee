"""The end-to-end demo on the simulated world (the README's main job).

1. simulate a data set: the prior and new objects, every action, ``train_reps + test_reps``
   trials each (resumed if the file exists);
2. extract the feature observations;
3. build the prior knowledge on the prior objects' first ``train_reps`` trials;
4. learn the new objects with APTKT, APTKT with auxiliary features and the baseline,
   ``trials`` runs each, drawing
   observations from the first ``train_reps`` trials and testing on the rest;
5. print a table and, per action and new object, the prior object APTKT learned from with λ
   or why not; plot the learning curves (with chance level and 95 % bands), the final models'
   confusion between the new objects and the relatedness of new and prior objects; write
   every number and ``report.md`` to the output directory.

Accuracy is reported two ways everywhere: the mean over actions of each action's model on its
own test observations (the paper's measure), and all actions' posteriors fused.
A quick-size and a full-size result never share a directory: the second refuses to start.
"""

from __future__ import annotations

import json
import os
import platform
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from aptkt import __version__
from aptkt.actions import PAPER_ACTIONS
from aptkt.errors import ConfigError
from aptkt.experiments.aggregate import mean_band
from aptkt.experiments.executors import LocalExecutor
from aptkt.experiments.plots import figure, label_shares, learning_curves, save_figure
from aptkt.experiments.relatedness_plot import plot_relatedness, relatedness
from aptkt.experiments.runs import RunSpec, flatten, run_many
from aptkt.experiments.tables import write_csv
from aptkt.files import write_json_atomically, write_text_atomically
from aptkt.learning import GPSettings, LearnerConfig, PriorKnowledge
from aptkt.learning.dataset import extract_features, load_observations, stale_features
from aptkt.learning.transfer_summary import summary_lines
from aptkt.progress import Progress
from aptkt.runtime.generation import GenerationPlan, complete_kept

__all__ = ["DemoSettings", "report_results", "run_demo", "DEMO_PRIORS", "DEMO_NEW"]

#: Three prior objects, each related to one new object (paper §5.1).
DEMO_PRIORS = ("rough_sponge", "paper_box", "metal_toolbox")
#: The paper's five new objects.
DEMO_NEW = ("smooth_sponge", "hard_box", "biscuit_box", "mouse_pad", "bamboo_board")


@dataclass
class DemoSettings:
    output: Path = Path("aptkt-demo")
    seed: int = 0
    jobs: int = field(default_factory=lambda: os.cpu_count() or 1)
    trials: int = 3
    budget: int = LearnerConfig.budget
    train_reps: int = 10
    test_reps: int = 10
    actions: tuple[str, ...] = tuple(PAPER_ACTIONS)
    priors: tuple[str, ...] = DEMO_PRIORS
    new_objects: tuple[str, ...] = DEMO_NEW
    eps_neg: float = LearnerConfig.eps_neg
    eps_explor: float | None = LearnerConfig.eps_explor
    size: str = "full"  # "quick" for the reduced size; results of two sizes never mix

    @classmethod
    def quick(cls, **overrides: Any) -> DemoSettings:
        """A reduced size for tests: runs in well under a minute."""
        base = cls(
            trials=1,
            budget=4,
            train_reps=4,
            test_reps=3,
            actions=("P2", "S3", "C1"),
            new_objects=DEMO_NEW[:3],
            size="quick",
        )
        return replace(base, **overrides)


def _say(msg: str) -> None:
    print(msg, flush=True)


def run_demo(s: DemoSettings, *, progress: bool = True) -> dict[str, Any]:
    t_start = time.perf_counter()
    out = Path(s.output)
    _refuse_other_size(out, s.size)
    out.mkdir(parents=True, exist_ok=True)
    data = out / "data.h5"
    prior_path = out / "prior.npz"
    _simulate(s, data, progress)

    _say("[2/5] extracting features")
    trials = (tuple(range(s.train_reps)), tuple(range(s.train_reps, s.train_reps + s.test_reps)))
    # One pool of worker processes for the features and the learning runs, so that the runs
    # start in workers that are already up.
    executor = LocalExecutor(s.jobs)
    try:
        gp = GPSettings()
        _build_prior(s, data, prior_path, trials[0], gp, executor, progress)
        _say(
            f"[4/5] learning {len(s.new_objects)} new objects: APTKT (with and without auxiliary features) "
            f"vs baseline, {s.trials} runs each, "
            f"budget {s.budget}, on {s.jobs} process(es)"
        )
        methods = _methods(s, gp)
        specs = _specs(s, methods, data, prior_path, trials)
        bar = Progress(len(specs), "run", "learning", enabled=progress)
        results = run_many(specs, progress=bar.update, executor=executor)
        bar.close()
    finally:
        executor.close()
    rows = flatten(results)

    _say("[5/5] results")
    summary = report_results(
        out,
        rows,
        methods,
        s.new_objects,
        budget=s.budget,
        title=f"{len(s.new_objects)} new objects, priors: {', '.join(s.priors)}",
        head={
            "software_version": __version__,
            "python": platform.python_version(),
            "settings": {k: (str(v) if isinstance(v, Path) else v) for k, v in asdict(s).items()},
            "learner": {name: cfg.to_dict() for name, cfg in methods.items()},
        },
        size=s.size,
        files={"data": str(data), "prior": str(prior_path)},
        t_start=t_start,
    )
    _say(f"      done in {summary['seconds']:.0f} s")
    return summary


def _simulate(s: DemoSettings, data: Path, progress: bool) -> None:
    """Step 1: the demo's data set on the simulated world (completed if it exists)."""
    reps = s.train_reps + s.test_reps
    objects = tuple(s.priors) + tuple(s.new_objects)
    actions = tuple(PAPER_ACTIONS[a] for a in s.actions)
    _say(
        f"[1/5] simulating {len(objects)} objects x {len(actions)} actions x {reps} trials -> {data}"
    )
    plan = GenerationPlan(objects, actions, reps, s.seed)
    info = complete_kept(
        data, plan, jobs=s.jobs, progress=progress, say=lambda m: _say(f"      {m}")
    )
    _say(
        f"      {info['recordings']} recordings, {info['file_bytes'] / 1e6:.1f} MB "
        f"({info['simulated']} simulated now, {info['wall_seconds']:.0f} s)"
    )


def _build_prior(
    s: DemoSettings,
    data: Path,
    prior_path: Path,
    train_trials: tuple[int, ...],
    gp: GPSettings,
    executor: LocalExecutor,
    progress: bool,
) -> None:
    """Steps 2 and 3: the features, stored in the data set, and the prior knowledge."""
    todo = stale_features(data, s.actions)
    if todo:  # stored once, so the learning runs (and a re-run) read them
        extract_features(
            data, actions=todo, progress=progress, parallel_map=executor.imap_unordered
        )
    prior_table = load_observations(
        data, actions=s.actions, objects=s.priors, trials=train_trials, progress=progress
    )
    _say(f"[3/5] building prior knowledge on {', '.join(s.priors)} -> {prior_path}")
    prior = PriorKnowledge.build(prior_table, gp=gp, seed=s.seed)
    prior.save(prior_path)
    for row in prior.summary():
        w = ", ".join(f"{m} {v:.2f}" for m, v in zip(row["modalities"], row["weights_mean"]))
        _say(f"      {row['action']}: {row['observations']} observations, modality weights {w}")


def _methods(s: DemoSettings, gp: GPSettings) -> dict[str, LearnerConfig]:
    """The compared learners: APTKT with and without auxiliary features, and the baseline."""
    aptkt = LearnerConfig(
        transfer="paper", eps_neg=s.eps_neg, eps_explor=s.eps_explor, budget=s.budget, gp=gp
    )
    return {
        "APTKT": aptkt,
        "APTKT+aux": replace(aptkt, auxiliary=True),
        "baseline": LearnerConfig(transfer="none", eps_explor=s.eps_explor, budget=s.budget, gp=gp),
    }


def _specs(
    s: DemoSettings,
    methods: dict[str, LearnerConfig],
    data: Path,
    prior_path: Path,
    trials: tuple[tuple[int, ...], tuple[int, ...]],
) -> list[RunSpec]:
    """Every run: each method on each trial's pool order (the trial's seed)."""
    return [
        RunSpec(
            method=name,
            config=replace(cfg, seed=s.seed + t),
            data=str(data),
            actions=s.actions,
            new_objects=s.new_objects,
            pool_trials=trials[0],
            test_trials=trials[1],
            prior=str(prior_path),
            pool_seed=s.seed + t,
            tags={"run": t},
        )
        for t in range(s.trials)
        for name, cfg in methods.items()
    ]


def report_results(
    out: Path,
    rows: list[dict[str, Any]],
    methods: dict[str, LearnerConfig],
    new_objects: tuple[str, ...],
    *,
    budget: int,
    title: str,
    head: dict[str, Any],
    size: str,
    files: dict[str, str],
    t_start: float,
    say: Any = _say,
) -> dict[str, Any]:
    """The demo's results from its runs' step rows — printed table and transfer lines,
    learning curves, confusion matrices, relatedness heat-maps, ``results.csv``,
    ``confusion.csv``, ``summary.json`` and ``report.md`` — shared with learning from a feature
    table (:mod:`aptkt.experiments.table_learning`)."""
    new_objects = tuple(new_objects)
    curves = _curves(rows, methods)
    fused = _curves(rows, methods, key="fused_accuracy")
    x = np.arange(budget + 1)
    chance = 1.0 / len(new_objects)
    table = _table(curves, fused, x, chance)
    for line in table:
        say("      " + line)
    transfer = _transfer(rows, methods)
    for i, (name, lines) in enumerate(transfer.items()):
        if i == 0:  # the others in report.md
            say(
                f"      transfer at the end of the runs ({name}; per action: new object <- "
                "prior object, or why not):"
            )
            for line in lines:
                say("        " + line)
    plots = _plot_curves(rows, curves, fused, x, chance, title, out / "learning_curves")
    confusion = _confusion(rows, ("baseline", "APTKT"), new_objects)
    plots += _plot_confusion(confusion, new_objects, out / "confusion")
    heat_maps = {}
    for name in transfer:
        stem = out / f"transfer_{name.replace('+', '_')}"
        finals = _final_transfer(rows, name)
        heat_maps[name] = plot_relatedness(
            relatedness(finals, methods[name]), stem, method=name, config=methods[name]
        )
        plots += heat_maps[name]
    write_csv(
        out / "confusion.csv",
        [
            {
                "method": m,
                "object": o,
                **{f"predicted {p}": int(c[i, k]) for k, p in enumerate(new_objects)},
            }
            for m, c in confusion.items()
            for i, o in enumerate(new_objects)
        ],
    )
    nested = ("confusion", "final_transfer")  # in summary.json and report.md instead
    write_csv(out / "results.csv", [{k: v for k, v in r.items() if k not in nested} for r in rows])
    summary = {
        **head,
        "table": table,
        "size": size,
        "chance": chance,
        "final_mean_accuracy": {m: float(np.nanmean(c[:, -1])) for m, c in curves.items()},
        "initial_mean_accuracy": {m: float(np.nanmean(c[:, 0])) for m, c in curves.items()},
        "final_fused_accuracy": {m: float(np.nanmean(c[:, -1])) for m, c in fused.items()},
        "initial_fused_accuracy": {m: float(np.nanmean(c[:, 0])) for m, c in fused.items()},
        "final_confusion": {m: c.astype(int).tolist() for m, c in confusion.items()},
        "transfer": transfer,
        "seconds": time.perf_counter() - t_start,
        "files": {
            **files,
            "results": str(out / "results.csv"),
            "confusion": str(out / "confusion.csv"),
            "plots": [str(p) for p in plots],
        },
    }
    write_json_atomically(out / "summary.json", summary, ConfigError, indent=2)
    write_text_atomically(
        out / "report.md",
        _report_markdown(title, table, transfer, out, plots, heat_maps),
        ConfigError,
    )
    say(f"      report: {out / 'report.md'}; plots: {', '.join(str(p) for p in plots)}")
    say(
        f"      every step of every run: {out / 'results.csv'}; settings and table: {out / 'summary.json'}"
    )
    return summary


def _actions(rows: list[dict[str, Any]]) -> list[str]:
    """The actions learned, from the rows' ``accuracy[<action>]`` columns."""
    found = (k[len("accuracy[") : -1] for r in rows for k in r if k.startswith("accuracy["))
    return list(dict.fromkeys(found))


def _plot_curves(
    rows: list[dict[str, Any]],
    curves: dict[str, np.ndarray],
    fused: dict[str, np.ndarray],
    x: np.ndarray,
    chance: float,
    title: str,
    stem: Path,
) -> list[Path]:
    """The learning curves: each action's model averaged over actions and, with more than one
    action, all actions fused beside it (with one, the two are the same curve)."""
    panels = {"mean accuracy of the actions' models": curves}
    actions = _actions(rows)
    if len(actions) > 1:
        panels["all actions fused"] = fused
    else:
        panels = {f"accuracy of the {actions[0]} model" if actions else "accuracy": curves}
    fig, axes = figure(
        1, len(panels), figsize=(5.5 * len(panels) + 0.5, 4.4), squeeze=False, layout="constrained"
    )
    for ax, (name, values) in zip(axes[0], panels.items()):
        n = next(iter(values.values())).shape[1]
        learning_curves(ax, values, x[:n], chance=chance, title=name)
    fig.suptitle(title)
    return save_figure(fig, stem)


def _final_transfer(rows: list[dict[str, Any]], method: str) -> list[dict[str, Any]]:
    """The transfer decisions in force at the end of each of the method's runs."""
    return [r["final_transfer"] for r in rows if r["method"] == method and "final_transfer" in r]


def _transfer(
    rows: list[dict[str, Any]], methods: dict[str, LearnerConfig]
) -> dict[str, list[str]]:
    """Per method that transfers, what its runs transferred in the end, or why not."""
    out = {}
    for name, cfg in methods.items():
        finals = _final_transfer(rows, name)
        if cfg.transfers and finals:
            out[name] = summary_lines(finals, cfg)
    return out


def _report_markdown(
    title: str,
    table: list[str],
    transfer: dict[str, list[str]],
    out: Path,
    plots: list[Path],
    heat_maps: dict[str, list[Path]],
) -> str:
    """report.md: the accuracy table, the learning curves, and per method what each new
    object learned from."""
    png = {p.stem: p.name for p in plots if p.suffix == ".png"}
    lines = [f"# {title}", "", "## Accuracy", "", "```text", *table, "```", ""]
    lines += (
        [f"![learning curves]({png['learning_curves']})", ""] if "learning_curves" in png else []
    )
    lines += (
        [f"![confusion between the new objects]({png['confusion']})", ""]
        if "confusion" in png
        else []
    )
    lines += [
        "## Transfer",
        "",
        "Per action and new object: the prior object it learned from with λ (Eq. 2–3) and the "
        "log odds that let it through, or why nothing was transferred — Eq. 3's eps_neg, or "
        "the second cut-off: by default the same-object cut-off (the library's log odds that "
        "the new object is that prior object, against every other one and an object it does "
        "not hold, must exceed the margin; with --cutoff evidence, the log Bayes factor of the "
        "coupling). The decisions are those in force at the end of each run; outcomes are "
        "counted over runs, with their mean p̄, λ and log odds.",
        "",
    ]
    if not transfer:
        lines += ["No method of this run transfers.", ""]
    for name, text in transfer.items():
        lines += [f"### {name}", "", "```text", *text, "```", ""]
        for p in heat_maps.get(name, []):
            if p.suffix == ".png":
                lines += [
                    f"![{name}: relatedness of new and prior objects]({p.name})",
                    "",
                    "Cells: p̄, how much the new object (row) is like the prior object (column), "
                    "mean over runs; solid red outline: learned from it (λ, in how many runs); "
                    "dashed grey: the second cut-off stopped it (its log odds, in how many runs).",
                    "",
                ]
    return "\n".join(lines)


def _curves(
    rows: list[dict[str, Any]], methods: dict[str, Any], key: str = "mean_accuracy"
) -> dict[str, np.ndarray]:
    curves = {}
    for name in methods:
        per_run: dict[int, list[tuple[int, float]]] = {}
        for r in rows:
            if r["method"] == name:
                per_run.setdefault(r["run"], []).append((r["step"], r[key]))
        length = max(len(v) for v in per_run.values())
        arr = np.full((len(per_run), length), np.nan)
        for i, (_, steps) in enumerate(sorted(per_run.items())):
            for step, value in steps:
                arr[i, step] = value
        curves[name] = arr
    return curves


def _refuse_other_size(out: Path, size: str) -> None:
    """A result of the other size in ``out`` would be overwritten piece by piece: refuse."""
    summary = out / "summary.json"
    if not summary.exists():
        return
    try:
        found = json.loads(summary.read_text()).get("size", "full")
    except (OSError, ValueError):
        raise ConfigError(
            f"{out} holds a summary.json that cannot be read; choose another --output"
        ) from None
    if found != size:
        raise ConfigError(
            f"{out} holds a {found}-size demo result; a {size}-size run would overwrite it. "
            f"Choose another --output (e.g. {out}-{size})"
        )


def _cell(values: np.ndarray) -> str:
    mean, low, high = (float(v[0]) for v in mean_band(values[:, None]))
    if not np.isfinite(low):
        return f"{mean:.3f}"
    return f"{mean:.3f}±{(high - low) / 2:.3f}"


def _table(
    curves: dict[str, np.ndarray], fused: dict[str, np.ndarray], x: np.ndarray, chance: float
) -> list[str]:
    """Mean accuracy (± half-width of the 95 % interval over runs) at a few steps, per action
    averaged and all actions fused, beside each other."""
    n = min(c.shape[1] for c in curves.values())
    marks = sorted({0, n // 4, n // 2, n - 1})
    head = f"{'method':<10}{'accuracy':<16}" + "".join(f"{f'+{x[m]} obs':>16}" for m in marks)
    lines = [head, "-" * len(head)]
    for name, c in curves.items():
        for kind, values in (("action mean", c), ("fused", fused[name])):
            cells = "".join(f"{_cell(values[:, m]):>16}" for m in marks)
            lines.append(f"{name if kind == 'action mean' else '':<10}{kind:<16}{cells}")
    lines.append(
        f"chance level {chance:.3f}; ± is half the 95 % interval over {c.shape[0]} run(s); "
        "action mean = each action's model on its own test observations, averaged over actions "
        "(the paper's measure); fused = all actions' posteriors combined"
    )
    return lines


def _confusion(
    rows: list[dict[str, Any]], methods: tuple[str, ...], objects: tuple[str, ...]
) -> dict[str, np.ndarray]:
    """Per method, the final models' confusion counts summed over runs (rows: true object)."""
    out = {}
    for m in methods:
        total = np.zeros((len(objects), len(objects)), dtype=int)
        for r in rows:
            if r["method"] == m and "confusion" in r:
                total += np.asarray(r["confusion"], dtype=int)
        out[m] = total
    return out


def _plot_confusion(confusion: dict[str, np.ndarray], objects: tuple[str, ...], stem: Path):
    names = [o.replace("_", " ") for o in objects]
    fig, axes = figure(
        1,
        len(confusion),
        figsize=(4.0 * len(confusion) + 2.5, 4.6),
        squeeze=False,
        layout="constrained",
    )
    for panel, (ax, (method, counts)) in enumerate(zip(axes[0], confusion.items())):
        share = counts / np.maximum(counts.sum(axis=1, keepdims=True), 1)
        im = ax.imshow(share, vmin=0, vmax=1, cmap="Blues")
        label_shares(ax, share)
        ax.set_xticks(range(len(objects)), names, rotation=45, ha="right", fontsize=8)
        ax.set_yticks(range(len(objects)), names if panel == 0 else [], fontsize=8)
        ax.set_xlabel("predicted object")
        if panel == 0:  # the panels share their rows: one set of row labels
            ax.set_ylabel("true object")
        ax.set_title(f"{method}: final models", fontsize=10)
    fig.colorbar(
        im, ax=axes[0].tolist(), shrink=0.8, label="share of the true object's test observations"
    )
    fig.suptitle("confusion between the new objects (every action's model, all runs)")
    return save_figure(fig, stem)
