"""The benchmark run: choose the attackers, plan the tasks, execute them, collect the rows.

One row per lens x attack chain x seed (`benchmark.results.schema.Row`). The runner, not the attacker,
computes every metric, so all attackers are scored the same way. Every reader runs on the
sensor image and on every restorer's output (the chained attack: deblur, then read). An
attacker that fails to load, fit, restore or read gives failed rows; the rest of the run goes on.

Modules of a run (this package), each with one job: `config` (what is asked), `planning` (which
tasks), `tasks` (one task, cached), `executors` (where tasks run), `evaluation` (sense, restore, read,
score), `rows` (rows through the schema), and this module (orchestration).
"""

from __future__ import annotations

import hashlib
import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import attacks
from benchmark.runner import executors, sandbox
from benchmark.runner.planning import AttackerRef, Task, plan, run_directory
from benchmark.runner.tasks import TaskResult
from benchmark.store import cipher
from benchmark.store.provenance import provenance
from benchmark.runner.config import RunConfig
from benchmark.runner.defaults import CASCADE, STANDARD_ENSEMBLE, chain_parts
from benchmark.results.schema import Results as ResultsFile
from benchmark.results.schema import Row, RowError, chain_name, settings_hash, write_results

log = logging.getLogger(__name__)


@dataclass
class RunOutput:
    rows: list[Row]
    settings: dict[str, dict]            # settings hash -> lens + attacker settings of the rows
    plates: list[dict]
    pictures: list[Path]                 # sample images written by the tasks
    lens_info: dict[str, dict]           # per lens: learned coefficients and spec
    bound_curves: dict[str, tuple]       # per lens: (plate widths px, Fano ceiling) of the first seed
    failed: list[Row] = field(default_factory=list)  # the rows with status "failed"
    picture_key: bytes | None = None     # a sealed run's: its scene tasks' pictures are encrypted under it


@dataclass(frozen=True)
class Selection:
    """The attackers of a run: restorers and readers that loaded, and those that did not."""

    restorers: list[AttackerRef]
    readers: list[AttackerRef]
    failures: list[attacks.PluginFailure]


def select_attackers(requested: list[str] | None, isolate: bool = False) -> Selection:
    """Load the requested attackers (None: every registered one run by default), one at a time.

    isolate: a plugin not shipped with the suite (a file spec, another distribution's entry point) is
    loaded in a process of its own (``sandbox``), here to learn its name and kind, and in every task it
    runs in (its spec is ``sandbox.ISOLATED`` + the spec); it is never imported into the runner.

    Raises:
        UnknownAttackError: a requested name is not registered (a typo, not a broken plugin).
        DuplicatePluginError: two attackers of the run share a name; the message names both sources.
    """
    selected, failures = attacks.load_all(requested, load_outside=sandbox.isolated if isolate else None)
    failed = {f.name for f in failures}
    # load_all keeps the order of the request: the i-th attacker that loaded came from the i-th spec that did.
    specs = [a.name for a in selected] if requested is None else [s for s in dict.fromkeys(requested)
                                                                   if s not in failed]
    for a in selected:  # each task loads its own: a stand-in's process ends here
        if sandbox.is_stand_in(a):
            a.close()  # type: ignore[attr-defined]
    specs = [sandbox.ISOLATED + spec if sandbox.is_stand_in(a) else spec for a, spec in zip(selected, specs)]
    chosen = [(a, spec) for a, spec in zip(selected, specs) if requested is not None or a.run_by_default]
    return Selection([AttackerRef(a.name, spec, file_key(spec)) for a, spec in chosen if isinstance(a, attacks.Restorer)],
                     [AttackerRef(a.name, spec, file_key(spec)) for a, spec in chosen if isinstance(a, attacks.Reader)],
                     failures)


def with_cascades(selection: Selection, isolate: bool = False) -> tuple[Selection, tuple[str, ...]]:
    """The full cross product of `selection` (attackers that run by default) with the standard ensemble's
    cascade after it: the selection with the cascade's readers added, and the chains to measure (every
    restorer; every reader on the sensor image and after every restorer; then ``CASCADE``, which reads only
    the plates no chain of the cross product read)."""
    parts = [p for chain in CASCADE for p in chain_parts(chain)]
    extra = select_attackers([p for p in parts if p not in {r.name for r in selection.readers}], isolate)
    restorers = [r.name for r in selection.restorers]
    readers = [r.name for r in selection.readers]
    chains = (*restorers, *readers, *(chain_name(a, b) for a in restorers for b in readers), *CASCADE)
    return Selection(selection.restorers + extra.restorers, selection.readers + extra.readers,
                     selection.failures + extra.failures), chains


def file_key(spec: str) -> str:
    """For a file plugin ('path/file.py:Class', isolated or not), a hash of the file's text, which keys the
    run's cache with its name: an edited plugin is computed again, not served the results of its old text
    (the modules it imports are not hashed). "" for a registered name."""
    spec = spec.removeprefix(sandbox.ISOLATED)
    if ".py:" not in spec:
        return ""
    path = Path(spec.rpartition(":")[0]).expanduser()
    try:
        return "file-" + hashlib.sha256(path.read_bytes()).hexdigest()[:16]
    except OSError:  # it loaded a moment ago; gone now: its tasks fail to load it and say so
        return ""


def standard_attackers() -> list[str]:
    """The attackers of the standard ensemble (`STANDARD_ENSEMBLE`), each once, in order of first mention."""
    return list(dict.fromkeys(part for chain in STANDARD_ENSEMBLE for part in chain_parts(chain)))


def load_failure_rows(cfg: RunConfig, failures: list[attacks.PluginFailure]) -> tuple[list[Row], dict[str, dict]]:
    """One failed row per (lens, seed) for each attacker that did not load.

    Its kind is the class's when it was found (reader or restorer); an attacker whose module did
    not even import is reported as a restorer row (its kind is unknown).
    """
    rows, settings = [], {}
    for failure in failures:
        kind = failure.kind or "restorer"
        described = {"attack": failure.name, "load_error": failure.error}
        key = settings_hash(described)
        settings[key] = described
        for seed in cfg.seeds:
            for lens in cfg.lenses:
                rows.append(Row.failed(kind, lens, failure.name, seed, cfg.profile.name, cfg.scenes,
                                       RowError(failure.name, "load", failure.error), **{kind: failure.name},
                                       settings_hash=key, provenance=provenance(cfg.device)))
    return rows, settings


def run(cfg: RunConfig, executor: str = "local", selection: Selection | None = None,
        partial: Path | None = None, on_task: Callable[[Task], None] | None = None) -> RunOutput:
    """Plan the run's tasks, execute them (locally or on Ray), and collect rows in plan order.

    `selection` is `select_attackers(cfg.attacks)` when the caller has checked it already. With
    `partial`, the rows of every task completed so far are rewritten there (a results file, meta
    "partial": true) as each task completes, so a run that dies leaves them on disk; the task
    results themselves stay in the cache, and a rerun resumes from them. `on_task` is called with each task
    as it completes (a progress bar's hook)."""
    selection = selection or select_attackers(cfg.attacks)
    planned = plan(cfg, selection.restorers, selection.readers)
    directory = run_directory(cfg, selection.restorers, selection.readers)
    failures = load_failure_rows(cfg, selection.failures)
    done: dict[str, TaskResult] = {}

    def on_result(task: Task, result: TaskResult) -> None:
        done[task.key] = result
        if on_task is not None:
            on_task(task)
        if partial is None:
            return
        so_far = collect([t for t in planned if t.key in done], done, directory, failures)
        write_results(partial, ResultsFile(so_far.rows, so_far.settings, {  # type: ignore[arg-type]
            "partial": True, "tasks_done": len(done), "tasks_total": len(planned),
            "task_results": str(directory)}))

    listening = partial is not None or on_task is not None
    results = executors.get(executor).run(planned, cfg, directory, on_result if listening else None)
    output = collect(planned, results, directory, failures)
    output.picture_key = cipher.run_key(cfg.scene_seeds)
    return output


def collect(planned: list[Task], results: dict[str, TaskResult], directory: Path,
            failures: tuple[list[Row], dict[str, dict]]) -> RunOutput:
    """The run's output from the results of `planned` (in plan order), after the rows of the
    attackers that did not load (`failures`, from `load_failure_rows`)."""
    out = RunOutput(list(failures[0]), dict(failures[1]), [], [], {}, {})
    for task in planned:
        result = results[task.key]
        out.rows.extend(result.rows)
        out.settings.update(result.settings)
        out.plates.extend(result.plates)
        out.pictures.extend(directory / task.key / name for name in result.meta.get("pictures", []))
        # A lens task that failed gives failed rows and no lens facts; the lens's other rows still count.
        if task.kind == "lens" and task.lens not in out.lens_info and "spec" in result.meta:
            out.lens_info[task.lens] = {k: result.meta[k] for k in ("coefficients_um", "spec")}
        if task.kind == "bound" and task.lens not in out.bound_curves and "curve" in result.meta:
            curve = result.meta["curve"]
            out.bound_curves[task.lens] = (curve["width_px"], curve["ceiling"])
    out.failed = [r for r in out.rows if not r.ok]
    return out
