"""Generate data sets on the simulated world: the paper's test set or any custom one.

Every trial is simulated from its own seed (world seed, object, action, trial), so the data do
not depend on the order of trials or on how many processes share the work; recordings are
written in plan order, so the same plan and seed give the same file content bit for bit.
"""

from __future__ import annotations

import concurrent.futures as cf
import json
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from threadpoolctl import threadpool_limits

from aptkt.actions import PAPER_ACTIONS, ExploratoryAction
from aptkt.data.codec import PackedRecording, pack_recording
from aptkt.errors import DatasetError, InvalidInputError, WorkerDiedError
from aptkt.runtime.grid import TrialGrid
from aptkt.runtime.trial_file import TrialFile
from aptkt.runtime.worker_start import WorkerPool, start_worker
from aptkt.sim.noise import FITTED, PHYSICAL, NoiseLevel
from aptkt.sim.objects import default_library, load_library
from aptkt.sim.world import SimWorld

__all__ = [
    "GenerationPlan",
    "generate",
    "paper_plan",
    "other_world",
    "complete_kept",
    "describe_noise",
]


@dataclass(frozen=True)
class GenerationPlan(TrialGrid):
    """Which trials to simulate: every action ``repetitions`` times on every object."""

    objects: tuple[str, ...]
    actions: tuple[ExploratoryAction, ...]
    repetitions: int = 20
    seed: int = 0
    first_trial: int = 0
    object_files: tuple[str, ...] = ()  # extra object libraries (TOML) for the world
    world_options: dict[str, Any] = field(default_factory=dict)  # e.g. {"patch_seed": 0}

    def __post_init__(self) -> None:
        if not self.objects or not self.actions:
            raise InvalidInputError("a plan needs at least one object and one action")
        if self.repetitions < 1 or self.first_trial < 0 or self.seed < 0:
            raise InvalidInputError("repetitions must be >= 1, first_trial and seed >= 0")
        names = [a.name for a in self.actions]
        if len(set(names)) != len(names):
            raise InvalidInputError(f"action names must be unique, got {names}")
        # The noise level is always written down: a file says which world made it, whatever
        # the default was then.
        noise = self.world_options.get("noise", FITTED)
        level = noise if isinstance(noise, NoiseLevel) else NoiseLevel.from_dict(noise)
        object.__setattr__(self, "world_options", {**self.world_options, "noise": level.to_dict()})

    @property
    def noise(self) -> NoiseLevel:
        return NoiseLevel.from_dict(self.world_options["noise"])

    def describe(self) -> dict[str, Any]:
        return {
            "generator": "aptkt.runtime.generation",
            "world": "aptkt.sim.SimWorld",
            "seed": self.seed,
            "objects": list(self.objects),
            "actions": [a.to_dict() for a in self.actions],
            "repetitions": self.repetitions,
            "first_trial": self.first_trial,
            "object_files": list(self.object_files),
            "world_options": dict(self.world_options),
        }


def paper_plan(seed: int = 0, repetitions: int = 20) -> GenerationPlan:
    """The paper's test set (§5.2): each of the 7 actions 20 times on each of the 15 objects."""

    return GenerationPlan(
        tuple(default_library()), tuple(PAPER_ACTIONS.values()), repetitions, seed
    )


# --------------------------------------------------------------------------- worker side
_WORLD = None


def _init_world(seed: int, object_files: tuple[str, ...], options: dict[str, Any]) -> None:
    global _WORLD

    library = load_library(*object_files) if object_files else default_library()
    _WORLD = SimWorld(library, seed=seed, **options)


def _simulate(job: tuple[str, dict[str, Any], int]) -> PackedRecording:
    """One trial, returned packed: raw integers already compressed into the file's chunks, so
    that the single writer only places bytes (a few kB per trial cross the process boundary,
    not a pickled object graph)."""
    obj, action, trial = job
    assert _WORLD is not None
    return pack_recording(_WORLD.explore(obj, ExploratoryAction.from_dict(action), trial))


# --------------------------------------------------------------------------- driver
def generate(
    path: str | Path,
    plan: GenerationPlan,
    *,
    jobs: int = 1,
    resume: bool = False,
    overwrite: bool = False,
    progress: bool | Callable[[int, int], None] = True,
) -> dict[str, Any]:
    """Simulate ``plan`` into ``path``. With ``resume`` an existing file is completed (trials
    already stored are skipped; a file whose writer died is repaired first). Returns a summary
    with the wall time and the file size."""
    t0 = time.perf_counter()

    def same_world(description: dict[str, Any]) -> None:
        stored = description.get("seed")
        if stored is not None and stored != plan.seed:
            raise DatasetError(f"{path} was generated with seed {stored}, not {plan.seed}")
        noise = stored_noise(description)
        if stored is not None and noise != plan.noise:
            raise DatasetError(
                f"{path} was generated with the noise level {describe_noise(noise)}, not "
                f"{describe_noise(plan.noise)}; completing it would mix two worlds (give "
                "another file, or --force to replace it)"
            )

    with TrialFile(
        path,
        plan,
        description=plan.describe(),
        resume=resume,
        overwrite=overwrite,
        check=same_world,
        progress=progress is True,
    ) as out:
        writer, bar = out.writer, out.bar
        for rec in _run(plan, out.todo, jobs, lambda: len(writer), out.path):
            writer.append_packed(rec)
            if bar is not None:
                # (Before the count: the line or bar the count brings shows this recording.)
                bar.note("done: {} {} trial {}".format(*rec.key))
                bar.update(1)
            elif callable(progress):
                progress(len(writer), len(plan))
    return out.summary(wall_seconds=time.perf_counter() - t0, simulated=len(out.todo))


def describe_noise(noise: NoiseLevel) -> str:
    return ", ".join(f"{k} {v:g}" for k, v in noise.to_dict().items())


def stored_noise(description: dict[str, Any]) -> NoiseLevel:
    """The noise level a data set was simulated at (a file from before levels were written down
    was made at the physical one)."""
    options = description.get("world_options") or {}
    return NoiseLevel.from_dict(options.get("noise", PHYSICAL.to_dict()))


def other_world(path: Path, plan: GenerationPlan) -> NoiseLevel | None:
    """The noise level of an existing data set at ``path`` if it is not ``plan``'s: a data set
    a command keeps to reuse (the demo's, reproduce's) is then simulated again."""
    from aptkt.data import DatasetReader

    if not path.exists():
        return None
    try:
        with DatasetReader(path) as rd:
            description = rd.description
    except (DatasetError, OSError):
        return None  # (the writer's own checks say what is wrong with it)
    if description.get("generator") != "aptkt.runtime.generation":
        return None
    noise = stored_noise(description)
    return noise if noise != plan.noise else None


def complete_kept(
    path: Path,
    plan: GenerationPlan,
    *,
    jobs: int,
    progress: bool | Callable[[int, int], None],
    say: Callable[[str], None],
) -> dict[str, Any]:
    """Complete a data set a command keeps to reuse (the demo's, reproduce's): resumed if it was
    simulated in this world, simulated again if at another noise level (an older default)."""
    stale = other_world(path, plan)
    if stale is not None:
        say(
            f"{path} was simulated at another noise level ({describe_noise(stale)}): "
            "simulating it again"
        )
    return generate(
        path,
        plan,
        jobs=jobs,
        resume=path.exists() and stale is None,
        overwrite=stale is not None,
        progress=progress,
    )


def _run(
    plan: GenerationPlan,
    todo: Sequence[tuple[str, ExploratoryAction, int]],
    jobs: int,
    written: Callable[[], int],
    path: Path,
) -> Iterator[PackedRecording]:
    args = (plan.seed, plan.object_files, plan.world_options)
    work = [(o, a.to_dict(), t) for o, a, t in todo]
    if jobs <= 1:
        _init_world(*args)
        # In this process BLAS has started already: limit it while simulating (see
        # aptkt.runtime.worker_start for why).
        with threadpool_limits(1, user_api="blas"):
            for job in work:
                yield _simulate(job)
        return
    workers = WorkerPool(
        jobs, initializer=start_worker, initargs=("aptkt.runtime.generation:_init_world", *args)
    )
    finished = False
    try:
        # Results come back in plan order, whichever process computed them.
        yield from workers.pool.map(_simulate, work, chunksize=4)
        finished = True
    except cf.process.BrokenProcessPool as exc:
        raise WorkerDiedError(
            f"a simulation worker process died abruptly (killed, out of memory or crashed); "
            f"{path} keeps the {written()} recordings written so far: run the same command "
            "with --resume to complete it"
        ) from exc
    finally:
        # Interrupted (or failed): what the workers hold would not be written anyway.
        if finished:
            workers.close()
        else:
            workers.end_now()


def describe_summary(info: dict[str, Any]) -> str:
    """A short human-readable summary of :func:`generate`'s result."""
    mb = info["file_bytes"] / 1e6
    return (
        f"{info['recordings']} recordings ({info['samples']} samples, {info['recorded_seconds']:.0f} s recorded) "
        f"in {info['wall_seconds']:.1f} s; {mb:.1f} MB ({info['bytes_per_sample']:.2f} bytes/sample)"
        + (
            f"; repaired a crashed file first ({info['repaired']} recordings kept)"
            if info.get("repaired")
            else ""
        )
    )


def dumps(info: dict[str, Any]) -> str:
    return json.dumps(info, indent=2, sort_keys=True, default=str)
