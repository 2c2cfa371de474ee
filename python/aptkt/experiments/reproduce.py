"""``aptkt reproduce``: the paper's experiments (§5.3–5.6) on the simulated world.

1. data: the given data set, or one generated for the chosen size (cached in the output
   directory, resumed if interrupted); features extracted once;
2. plan every requested figure: its prior-knowledge groups and its learning runs;
3. build the prior knowledge, then perform the runs — on local processes or a Dask cluster —
   storing each finished run at once (``runs/``), so a rerun resumes where it stopped;
4. per figure: plots (PNG, SVG), raw per-step results and curves (CSV), a report section;
5. ``report.md`` (our numbers beside the paper's), ``summary.json`` (every computed number),
   ``config.json`` (everything that makes the run repeat exactly).
"""

from __future__ import annotations

import datetime
import json
import os
import platform
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from aptkt import __version__
from aptkt.actions import PAPER_ACTIONS
from aptkt.data import DatasetReader
from aptkt.errors import ConfigError
from aptkt.experiments.batch import StoredSteps, build_priors, run_batch
from aptkt.experiments.beside_real import COLUMNS, beside_real, comparison, load_benchmark
from aptkt.experiments.executors import Executor, make_executor
from aptkt.experiments.figures import FIGURES
from aptkt.experiments.figures.base import METHODS, Context, Section
from aptkt.experiments.report import markdown_table, render_report
from aptkt.experiments.run_store import RunStore, data_fingerprint, run_key
from aptkt.experiments.runs import label
from aptkt.experiments.scale import Scale
from aptkt.files import open_atomically, write_json_atomically, write_text_atomically
from aptkt.learning import LearnerConfig
from aptkt.learning.dataset import extract_features, stale_features
from aptkt.runtime.generation import GenerationPlan, complete_kept
from aptkt.sim.noise import FITTED, NoiseLevel
from aptkt.sim.objects import default_library

__all__ = ["ReproduceSettings", "reproduce", "FIGURE_NAMES"]

FIGURE_NAMES = tuple(FIGURES)


@dataclass
class ReproduceSettings:
    """What ``aptkt reproduce`` was asked to do."""

    figures: tuple[str, ...] = FIGURE_NAMES
    output: Path = Path("aptkt-reproduce")
    data: Path | None = None
    quick: bool = False
    jobs: int = field(default_factory=lambda: os.cpu_count() or 1)
    scheduler: Any = None
    seed: int = 0
    progress: bool = True
    scale: Scale | None = None  # overrides the full / quick size (tests, custom studies)
    #: The learner every method starts from (``--reading`` and the method options).
    base: LearnerConfig = field(default_factory=LearnerConfig)
    command: str = ""
    #: An ``aptkt benchmark`` output directory whose real-data gains the report sets beside
    #: this run's.
    real_data: Path | None = None
    #: The simulated world's noise level (None: its default, :data:`aptkt.sim.noise.FITTED`).
    noise: NoiseLevel | None = None

    def resolved_scale(self) -> Scale:
        if self.scale is not None:
            return self.scale
        return Scale.quick() if self.quick else Scale.full()


def _say(msg: str) -> None:
    print(msg, flush=True)


def _paper_numbers(objects: Sequence[str]) -> dict[str, int]:
    """Each object's number in the paper (the library index); others numbered after them."""

    lib = default_library()
    out, extra = {}, 100
    for o in objects:
        if o in lib:
            out[o] = lib[o].index
        else:
            extra += 1
            out[o] = extra
    return out


def prepare_data(
    s: ReproduceSettings, scale: Scale, executor: Executor | None = None
) -> tuple[Path, dict[str, Any]]:
    """The data set to learn from (generated if none was given) with its features extracted."""

    info: dict[str, Any] = {}
    if s.data is not None:
        path = Path(s.data)
        if not path.is_file():
            raise ConfigError(f"--data {path}: no such file")
        info["source"] = "given"
    else:
        noise = s.noise if s.noise is not None else FITTED
        # (Another noise level is another world: its data set has its own name.)
        tag = "" if noise == FITTED else f"-noise-{_noise_tag(noise)}"
        path = s.output / f"data-{scale.name}-seed{s.seed}{tag}.h5"
        plan = GenerationPlan(
            scale.objects,
            tuple(PAPER_ACTIONS[a] for a in scale.actions),
            scale.repetitions,
            s.seed,
            world_options={"noise": noise.to_dict()},
        )
        _say(
            f"simulating the data set: {len(scale.objects)} objects × {len(scale.actions)} actions × "
            f"{scale.repetitions} trials -> {path}" + (" (resuming)" if path.exists() else "")
        )
        gen = complete_kept(path, plan, jobs=s.jobs, progress=s.progress, say=_say)
        info.update(
            source="generated",
            generation_seconds=gen["wall_seconds"],
            simulated_now=gen["simulated"],
        )
    with DatasetReader(path) as rd:
        keys = set(rd.keys())
        info["description"] = rd.description
    missing = [
        (o, a, t)
        for o in scale.objects
        for a in scale.actions
        for t in range(scale.repetitions)
        if (o, a, t) not in keys
    ]
    if missing:
        raise ConfigError(
            f"{path} lacks {len(missing)} recording(s) this size needs (objects {list(scale.objects)}, actions "
            f"{list(scale.actions)}, trials 0..{scale.repetitions - 1}); first missing: {missing[:3]}"
        )
    todo = stale_features(path, scale.actions)
    if todo:
        _say(f"extracting features of {', '.join(todo)} into {path}")
        t0 = time.perf_counter()
        extract_features(
            path,
            actions=todo,
            progress=s.progress,
            parallel_map=None if executor is None else executor.imap_unordered,
        )
        info["feature_seconds"] = time.perf_counter() - t0
    return path, info


def _noise_tag(noise: NoiseLevel) -> str:
    return "-".join(f"{v:g}" for v in noise.to_dict().values())


@dataclass
class FigureTask:
    """One figure's analysis after its runs: the context, its runs' specs, the run store."""

    name: str
    ctx: Context
    specs: Sequence[Any]
    store: str


def analyse_figure(task: FigureTask) -> tuple[Section, float]:
    """A figure's plots, tables and report section from its stored runs (only this figure's
    rows in this process's memory, see StoredSteps), and its ``specs.jsonl``; and the seconds
    it took."""
    t0 = time.perf_counter()
    store = RunStore(Path(task.store))
    fingerprint = task.ctx.fingerprint
    keys = [run_key(sp, fingerprint) for sp in task.specs]
    steps = StoredSteps(store, keys)
    rows = [r for sp, key in zip(task.specs, keys) for r in label(sp, steps[key])]
    section = FIGURES[task.name].analyse(task.ctx, rows)
    del rows
    with open_atomically(task.ctx.figure_dir(task.name) / "specs.jsonl", ConfigError) as fh:
        for sp, key in zip(task.specs, keys):
            fh.write(json.dumps({"key": key, **sp.to_dict()}) + "\n")
    return section, time.perf_counter() - t0


@dataclass
class _Done:
    """What a reproduction computed, before its report is written."""

    ctx: Context
    data: Path
    data_info: dict[str, Any]
    plans: dict[str, Any]
    specs: list[Any]
    batch: Any
    sections: list[Section]
    timings: dict[str, float]


def reproduce(s: ReproduceSettings) -> dict[str, Any]:
    """Run the requested figures; returns the summary also written to ``summary.json``."""
    unknown = [f for f in s.figures if f not in FIGURES]
    if unknown:
        raise ConfigError(f"unknown figure(s) {unknown}; choose from {list(FIGURES)} or 'all'")
    if s.seed < 0:
        raise ConfigError("--seed must be >= 0")
    t_start = time.perf_counter()
    scale = s.resolved_scale()
    out = Path(s.output)
    # The executor first: an unreachable cluster is reported before minutes of simulation.
    executor = make_executor(s.jobs, s.scheduler)
    try:
        out.mkdir(parents=True, exist_ok=True)
        done = _compute(s, scale, out, executor)
    finally:
        executor.close()
    return _write(s, scale, done, executor, time.perf_counter() - t_start)


def _compute(s: ReproduceSettings, scale: Scale, out: Path, executor: Executor) -> _Done:
    """The data, the plans, the prior knowledge, the runs and every figure's analysis."""
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    data, data_info = prepare_data(s, scale, executor)
    fingerprint = data_fingerprint(data)
    timings["data"] = time.perf_counter() - t0
    ctx = Context(
        scale=scale,
        seed=s.seed,
        data=str(data.resolve()),
        fingerprint=fingerprint,
        output=out.resolve(),
        index=_paper_numbers(scale.objects),
        base=s.base,
    )
    _say(f"planning {', '.join(s.figures)} ({scale.name} size) on {executor.description}")
    plans = {name: FIGURES[name].plan(ctx) for name in s.figures}
    tasks = {t.key: t for p in plans.values() for t in p.priors}
    t0 = time.perf_counter()
    build_priors(list(tasks.values()), executor, progress=s.progress)
    timings["prior_knowledge"] = time.perf_counter() - t0
    specs = [sp for p in plans.values() for sp in p.specs]
    t0 = time.perf_counter()
    batch = run_batch(specs, RunStore(out / "runs"), executor, fingerprint, progress=s.progress)
    timings["runs"] = time.perf_counter() - t0
    _say(
        f"{len(specs)} runs ({len(batch.steps)} distinct): {batch.computed} computed now, {batch.reused} from "
        f"{out / 'runs'}"
    )
    t0 = time.perf_counter()
    sections = _analyse(s.figures, ctx, plans, executor, timings)
    timings["analysis"] = time.perf_counter() - t0
    return _Done(ctx, data, data_info, plans, specs, batch, sections, timings)


def _analyse(
    figures: Sequence[str],
    ctx: Context,
    plans: dict[str, Any],
    executor: Executor,
    timings: dict[str, float],
) -> list[Section]:
    """The figures' sections, analysed side by side on the executor, the largest first (a
    run's rows have columns for each of its actions): each reads its own runs from the store,
    so no rows travel between processes, and the analysis is no longer a serial tail after
    the parallel runs."""
    order = sorted(figures, key=lambda name: -sum(len(sp.actions) for sp in plans[name].specs))
    figure_tasks = [FigureTask(n, ctx, plans[n].specs, str(ctx.output / "runs")) for n in order]
    by_name = {}
    for i, (section, seconds) in executor.imap_unordered(analyse_figure, figure_tasks):
        by_name[order[i]] = section
        timings[f"analysis_{order[i]}"] = seconds
        _say(f"analysed {order[i]} in {seconds:.1f} s ({len(by_name)}/{len(order)})")
    return [by_name[name] for name in figures]


def _write(
    s: ReproduceSettings, scale: Scale, done: _Done, executor: Executor, seconds: float
) -> dict[str, Any]:
    """config.json, the report (whole and per figure) and summary.json."""
    ctx, sections, batch, out = done.ctx, done.sections, done.batch, Path(s.output)
    config = _config(s, scale, ctx, done.data_info, done.plans)
    write_json_atomically(out / "config.json", config, ConfigError, indent=2)
    run_info: dict[str, Any] = {
        "command": s.command or f"aptkt reproduce {' '.join(s.figures)}",
        "software_version": __version__,
        "date": datetime.datetime.now().isoformat(timespec="seconds"),
        "seconds": seconds,
        "executor": executor.description,
        "data": str(done.data),
        "fingerprint": ctx.fingerprint,
        "seed": s.seed,
        "scale": scale.name,
        "settings": _flat_settings(scale, s, done.timings, batch),
    }
    numbers = {sec.figure: sec.numbers for sec in sections}
    real = load_benchmark(s.real_data) if s.real_data is not None else None
    rows = comparison(numbers, real) if real is not None else []
    beside = "\n".join(beside_real(real, rows))
    write_text_atomically(
        out / "report.md", render_report(sections, run_info) + "\n" + beside, ConfigError
    )
    for section in sections:
        write_text_atomically(
            ctx.figure_dir(section.figure) / "report.md",
            render_report([section], run_info),
            ConfigError,
        )
    summary = {
        "command": run_info["command"],
        "software_version": __version__,
        "date": run_info["date"],
        "figures": list(s.figures),
        "seconds": seconds,
        "timings": done.timings,
        "runs": {
            "total": len(done.specs),
            "distinct": len(batch.steps),
            "computed": batch.computed,
            "reused": batch.reused,
            "run_seconds_summed": run_info["settings"]["run seconds, summed over runs"],
        },
        "headlines": [h.__dict__ for sec in sections for h in sec.headlines],
        "numbers": numbers,
        "files": {sec.figure: sec.files for sec in sections},
        # What docs/results.md quotes of a run beside real data (``--real-data``).
        "beside_real": None
        if real is None
        else {
            "benchmark": {
                k: real.get(k) for k in ("table", "command", "software_version", "library")
            },
            "columns": list(COLUMNS),
            "rows": rows,
        },
    }
    write_json_atomically(out / "summary.json", summary, ConfigError, indent=2)
    _say(f"report: {out / 'report.md'}  ({seconds:.0f} s)")
    return summary


def _flat_settings(
    scale: Scale, s: ReproduceSettings, timings: dict[str, float], batch: Any
) -> dict[str, Any]:
    flat = {
        f"size.{k}": v
        for k, v in scale.to_dict().items()
        if k not in ("pool_trials", "test_trials")
    }
    flat["pool trials"] = f"{scale.pool_trials[0]}..{scale.pool_trials[-1]}"
    flat["test trials"] = f"{scale.test_trials[0]}..{scale.test_trials[-1]}"
    flat["root seed"] = s.seed
    flat["methods"] = "; ".join(f"{m}: {v}" for m, v in METHODS.items())
    flat["runs computed now / reused"] = f"{batch.computed} / {batch.reused}"
    # The runs' own time (their steps' wall time in the workers), kept with each stored run, so
    # it is known even when every run was read back from the store.
    flat["run seconds, summed over runs"] = round(batch.run_seconds, 1)
    flat.update({f"seconds.{k}": round(v, 1) for k, v in timings.items()})
    return flat


def _config(
    s: ReproduceSettings,
    scale: Scale,
    ctx: Context,
    data_info: dict[str, Any],
    plans: dict[str, Any],
) -> dict[str, Any]:

    return {
        "command": s.command,
        "repeat_with": f"aptkt reproduce {' '.join(s.figures) if len(s.figures) < len(FIGURES) else 'all'}"
        f"{' --quick' if s.quick else ''} --seed {s.seed} --data {ctx.data}",
        "software_version": __version__,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "platform": platform.platform(),
        "argv": sys.argv,
        "figures": list(s.figures),
        "seed": s.seed,
        "quick": s.quick,
        "jobs": s.jobs,
        "scheduler": None if s.scheduler is None else str(s.scheduler),
        "output": str(ctx.output),
        "data": {"path": ctx.data, "fingerprint": ctx.fingerprint, **data_info},
        "scale": scale.to_dict(),
        "learner": ctx.base.to_dict(),
        "methods": {m: dict(v) for m, v in METHODS.items()},
        "object_numbers": dict(ctx.index),
        "figures_plan": {
            name: {
                "runs": len(p.specs),
                "specs": f"{name}/specs.jsonl",
                "prior_knowledge": [{**t.to_dict(), "path": t.path} for t in p.priors],
            }
            for name, p in plans.items()
        },
    }


def describe_figures() -> str:
    return markdown_table(["name", "what"], [[n, m.TITLE] for n, m in FIGURES.items()])
