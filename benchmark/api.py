"""The Python API: what `python -m benchmark run` does, callable from a script or a notebook.

Example (README; tests/benchmark/test_api.py runs exactly these lines)::

    import benchmark
    print(benchmark.list_lenses(), benchmark.list_attacks())
    results = benchmark.run(lenses=["gp", "ideal"], attacks=["wiener-known-psf", "lpdr-oracle"], profile="smoke")
    table = results.table()  # pandas: one row per lens x attack x seed, metrics with 95 % intervals, status
    print(table[["lens", "attack", "status", "psnr_db", "psnr_db_ci_low", "psnr_db_ci_high", "plate_acc"]].to_string())

`run` validates every argument before any compute (errors name the argument and what would be
valid), plans the tasks, executes them (here, or on Ray), and returns `Results`: the typed rows
(`benchmark.results.schema.Row`), the settings they point at, and `table()`. With `out` it also writes
results.json, table.md, table.csv, pictures and charts there, as the CLI does. `plan` is the dry
run: which tasks are cached, which would be computed, and what they cost when last measured.

Attackers may be registered names, 'path/file.py:Class' specs, or Python objects: an
`attacks.Restorer` / `attacks.Reader` subclass or instance (see `benchmark.runner.attacker_objects` for
how they reach the tasks; an instance runs only with the local executor).
"""

from __future__ import annotations

import datetime as _dt
import logging
import secrets
import tempfile
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import attacks
import lenses
from benchmark.runner import attacker_objects, executors, runner, task_costs
from benchmark.store.cache import cache_root, config_hash
from benchmark.runner.diagnostics.known_warnings import silence_known_warnings
from benchmark.runner.planning import AttackerRef, Task, plan as plan_tasks, run_directory
from benchmark.store.profiles import Profile, get_profile
from benchmark.store.provenance import git_commit
from benchmark.runner.config import LensFile, RunConfig, training_scenes
from benchmark.scenes import PLATE_FORMAT, SCENE_SETS, load_scenes, plate_entropy_bits
from benchmark.runner.defaults import STANDARD_ENSEMBLE
from benchmark.runner.sandbox import ISOLATED
from benchmark.results.observer.published import fail_above_ceiling, load_study, run_violations
from benchmark.results.schema import Row, read_results, write_results
from benchmark.results.schema import Results as ResultsFile
from benchmark.runner.pictures import copy_picture
from benchmark.runner.tasks import is_cached

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["Plan", "PlannedTask", "Results", "list_attacks", "list_lenses", "list_scene_sets", "load_lens",
           "plan", "run"]

log = logging.getLogger(__name__)

AttackerLike = str | type[attacks.Attack] | attacks.Attack
# Identity columns of `Results.table()`, in order; metrics and their intervals follow.
ID_COLUMNS = ("kind", "lens", "attack", "restorer", "reader", "seed", "profile", "scenes", "status", "threat_model",
              "error_attacker", "error_stage", "error_message", "settings_hash")
CI_LOW, CI_HIGH = "_ci_low", "_ci_high"
# The rows of the tasks completed so far, rewritten as each completes (a run that dies leaves them).
PARTIAL_RESULTS = "results.partial.json"


# ---- discovery ------------------------------------------------------------------------------------

def list_lenses() -> dict[str, str]:
    """Registered lenses, name -> 'module:attr' (nothing is imported)."""
    return lenses.available()


def list_attacks() -> dict[str, str]:
    """Registered attackers, name -> 'module:attr' (nothing is imported)."""
    return attacks.available()


def list_scene_sets() -> dict[str, str]:
    """Scene sets, name -> description (`cityscapes` takes a path: 'cityscapes:PATH')."""
    return dict(SCENE_SETS)


def load_lens(name: str | Path, profile: str | Profile = "quick", seed: int = 0, device: str = "cpu",
              scenes: str = "synthetic") -> lenses.Lens:
    """A lens as a run would use it: a registered name or a .toml spec path.

    A co-designed lens (e.g. "gp") is trained with `profile` and `seed` on `scenes`' training
    set, or loaded from the cache (`PLB_CACHE`) when it was trained before; fixed lenses ignore
    these. Returns a `lenses.Lens` on `device`: `lens.psf()` (3, K, K), `lens(x)` for scenes
    x (B, 3, H, W) in [0, 1].
    """
    p = _profile(profile)
    return lenses.load(name, profile=p, seed=seed, device=check_device(device), cache_dir=cache_root(),
                       scenes=training_scenes(scenes)).to(device)


# ---- results --------------------------------------------------------------------------------------

@dataclass
class Results:
    """What a run produced.

    Attributes:
        rows: One `benchmark.results.schema.Row` per lens x attack chain x seed (failed attackers included,
            with status "failed" and their error).
        settings: Settings hash -> the lens and attacker settings the rows point at.
        meta: The run: profile settings, executor, wall time (s), and what the caller added.
        out: The folder the outputs were written to, or None.
        output: The run's other products (plate records, picture paths, lens info, bound curves);
            None for results read from a file.
    """

    rows: list[Row]
    settings: dict[str, dict[str, Any]] = field(default_factory=dict)
    meta: dict[str, Any] = field(default_factory=dict)
    out: Path | None = None
    output: runner.RunOutput | None = None

    @property
    def failed(self) -> list[Row]:
        """The rows with status "failed"."""
        return [r for r in self.rows if not r.ok]

    def table(self) -> pd.DataFrame:
        """The rows as a pandas DataFrame, one row per lens x attack x seed.

        Columns: `ID_COLUMNS` (kind, lens, attack, restorer, reader, seed, profile, scenes,
        status, threat_model, the error of a failed row, settings_hash), then each metric in
        the order first met (psnr_db in dB, ssim, plate_acc in [0, 1], fit_s in s, ...), a metric
        with a 95 % interval followed by `<metric>_ci_low` and `<metric>_ci_high`. A row without
        a metric has NaN there (a failed row has no metric at all).
        """
        import pandas as pd
        metrics: dict[str, bool] = {}  # name -> has an interval somewhere; insertion-ordered
        for r in self.rows:
            for name in r.metrics:
                metrics[name] = metrics.get(name, False) or name in r.intervals
        columns = list(ID_COLUMNS)
        for name, has_interval in metrics.items():
            columns += [name, name + CI_LOW, name + CI_HIGH] if has_interval else [name]
        records = []
        for r in self.rows:
            record: dict[str, Any] = {k: getattr(r, k) for k in ID_COLUMNS if not k.startswith("error_")}
            error = r.error.to_json() if r.error is not None else {}
            record.update({f"error_{k}": error.get(k) for k in ("attacker", "stage", "message")})
            for name in metrics:
                record[name] = r.metrics.get(name, float("nan"))
                low, high = r.intervals.get(name, (float("nan"), float("nan")))
                record[name + CI_LOW], record[name + CI_HIGH] = low, high
            records.append(record)
        return pd.DataFrame.from_records(records, columns=columns)

    def write(self, path: Path) -> Path:
        """Write the rows, settings and meta as a results.json (`benchmark.results.schema`)."""
        return write_results(Path(path), ResultsFile(self.rows, self.settings, self.meta))

    @classmethod
    def read(cls, path: Path) -> Results:
        """Results of an earlier run from its results.json (any schema version this code reads)."""
        stored = read_results(Path(path))
        return cls(stored.rows, stored.settings, stored.meta, out=Path(path).parent)


# ---- running --------------------------------------------------------------------------------------

def run(lenses: str | Sequence[str], attacks: Sequence[AttackerLike] | None = None, *,
        profile: str | Profile = "quick", seeds: int | Sequence[int] = (0,), scenes: str = "synthetic",
        device: str = "cpu", out: str | Path | None = None, executor: str = "local",
        plate_format: str | None = None, frames: int = 30, budget_s: float | None = None,
        all_chains: bool = False, meta: Mapping[str, Any] | None = None,
        on_task: Callable[[Task], None] | None = None, sealed: bool = False,
        scene_seeds: Mapping[int, int] | None = None, isolate: bool = True) -> Results:
    """Benchmark `lenses` against `attacks`; the CLI's `run` with the same meanings.

    Args:
        lenses: Registered lens names or .toml spec paths.
        attacks: Attackers: registered names, 'path/file.py:Class' specs, or attacks.Restorer /
            attacks.Reader subclasses or instances; every reader runs on the sensor image and after
            every restorer given. None: the standard ensemble (`STANDARD_ENSEMBLE`, docs/ensemble.md):
            its chains only.
        profile: "smoke", "quick" or "paper" (or a `Profile`).
        seeds: Seeds to run, distinct integers.
        scenes: "synthetic", "photos" or "cityscapes:PATH".
        device: "cpu" or "cuda[:N]".
        out: Folder for results.json, tables, pictures and charts (created); None writes none.
        executor: "local" (this process), "ray" (a local Ray instance), "ray:auto" or "ray://HOST:PORT".
        plate_format: Plate strings the privacy bound counts (L letter, D digit); None: the scenes'.
        frames: Frames of a static plate for the video bound (>= 1).
        budget_s: Wall-time budget (s) of each expensive step (an attacker's fit, restore or read;
            the bound); a step past it gives a failed row. None: no budget.
        all_chains: With `attacks` None: every attacker registered to run by default, every reader
            after every restorer (the full cross product), then the standard ensemble's cascade on the
            plates none of them read, instead of the standard ensemble.
        meta: Extra facts stored in results.json's meta (the CLI stores its command line).
        on_task: Called with each task (`benchmark.runner.planning.Task`) as it completes, computed or
            found in the cache (a progress bar's hook; `publish` uses it).
        sealed: Draw each seed's val scenes from a random seed (``secrets``) that no attacker is given
            (their fit contexts hold the run seed): a plugin cannot rebuild the test scenes from the
            public generator. The scene seeds go into the results' meta (``scene_seeds``) after the
            attackers ran; `scene_seeds` re-runs them.
        scene_seeds: The val scene seed of each run seed (a sealed run's, to reproduce it); None: the
            run seeds themselves (or random ones with `sealed`).
        isolate: Run each attacker not shipped with the suite (a file spec, another distribution's entry
            point) in a process of its own, handed only what its threat model grants: its code cannot
            reach the runner's scenes, plate texts or scoring (``benchmark.runner.sandbox``; about 1.3 s
            to start per attacker and task). False: in this process (your own plugin, under
            development; a sealed run refuses it). Objects passed as attackers stay in this process.

    Returns:
        `Results`; `Results.table()` is the DataFrame.

    Raises:
        ValueError (and LookupError subclasses for unknown names): a bad argument, before any compute.
    """
    git_commit()  # pinned now, as the code was imported: later commits do not re-stamp this run
    silence_known_warnings()
    _check_meta(meta)
    if out is not None and not isinstance(out, (str, Path)):
        raise TypeError(f"out must be a folder path (str or pathlib.Path) or None, got {type(out).__name__} {out!r}")
    if not isinstance(isolate, bool):
        raise TypeError(f"isolate must be True or False, got {isolate!r}")
    if sealed is True and not isolate:
        raise ValueError("a sealed run isolates its plugins (it is the run for plugins not shipped with the suite); "
                         "drop isolate=False")
    cfg, selection = _configure(lenses, attacks, profile, seeds, scenes, device, executor, plate_format, frames,
                                budget_s, all_chains, isolate=isolate)
    cfg.scene_seeds = _scene_seeds(cfg.seeds, sealed, scene_seeds)
    folder, created = prepare_out(Path(out)) if out is not None else (None, False)
    log.info("profile %s: %s", cfg.profile.name, cfg.profile.to_dict())
    t0 = time.perf_counter()
    try:
        output = runner.run(cfg, executor=executor, selection=selection,
                            partial=folder / PARTIAL_RESULTS if folder is not None else None, on_task=on_task)
    except BaseException:
        if created and folder is not None and not any(folder.iterdir()):
            folder.rmdir()
        raise
    run_meta = {**(meta or {}), "profile": cfg.profile.to_dict(), "executor": executor,
                "wall_s": time.perf_counter() - t0}
    isolated = sorted(r.name for r in selection.restorers + selection.readers if r.spec.startswith(ISOLATED))
    if isolated:
        run_meta["isolated"] = isolated
    if cfg.scene_seeds:  # written only now, after every attacker ran
        run_meta.update(sealed=bool(sealed), scene_seeds={str(k): v for k, v in sorted(cfg.scene_seeds.items())})
    output.rows = fail_above_ceiling(output.rows, run_violations(output.plates, output.lens_info, load_study())["violations"])
    output.failed = [r for r in output.rows if not r.ok]
    results = Results(output.rows, output.settings, run_meta, folder, output)
    if folder is not None:
        write_run_outputs(folder, results)
        (folder / PARTIAL_RESULTS).unlink(missing_ok=True)  # the whole results.json replaces it
    return results


def _configure(lens_names: str | Sequence[str], requested: Sequence[AttackerLike] | None, profile: str | Profile,
               seeds: int | Sequence[int], scenes: str, device: str, executor: str, plate_format: str | None,
               frames: int, budget_s: float | None, all_chains: bool = False, isolate: bool = True
               ) -> tuple[RunConfig, runner.Selection]:
    """Check every argument (before any compute) and choose the attackers (and with `attacks` None and
    not `all_chains`, the standard ensemble's chains)."""
    _check_types(lens_names=lens_names, profile=profile, scenes=scenes, device=device, executor=executor,
                 plate_format=plate_format)
    p = _profile(profile)
    names = [str(lens_names)] if isinstance(lens_names, (str, Path)) else [str(n) for n in lens_names]
    if not names:
        raise ValueError("lenses is empty; give at least one lens name or .toml spec (see benchmark.list_lenses())")
    names, lens_files = _lens_names(names)
    load_scenes(scenes, "val", 0, p.image_size, 0)  # validates the scene set name
    plate_format = PLATE_FORMAT if plate_format is None else plate_format  # "" is an error, not the default
    plate_entropy_bits(plate_format)  # validates the format before any work
    if plate_format != PLATE_FORMAT and scenes.split(":")[0] == "synthetic":
        log.warning("plate format %s: the bound counts such strings and the readers are told it, but the "
                    "synthetic scenes render %s plates, so readers trained for %s read them wrongly",
                    plate_format, PLATE_FORMAT, plate_format)
    if isinstance(frames, bool) or not isinstance(frames, int) or frames < 1:
        raise ValueError(f"frames must be an integer >= 1, got {frames!r}")
    if budget_s is not None and (isinstance(budget_s, bool) or not isinstance(budget_s, (int, float))
                                 or not budget_s > 0):
        raise ValueError(f"budget_s must be None or a number of seconds > 0, got {budget_s!r}")
    try:
        executors.get(executor)  # fails fast on a bad name or a missing Ray
    except RuntimeError as exc:  # Ray not installed: say so as for any other bad argument
        raise ValueError(f"executor {executor!r}: {exc}; or use executor 'local'") from None
    if not isinstance(all_chains, bool):
        raise TypeError(f"all_chains must be True or False, got {all_chains!r}")
    standard = requested is None and not all_chains
    selection = select_attackers(runner.standard_attackers() if standard else requested, remote=executor != "local",
                                 isolate=isolate)
    chains = STANDARD_ENSEMBLE if standard else None
    if requested is None and all_chains:
        selection, chains = runner.with_cascades(selection, isolate)
    cfg = RunConfig(lenses=names, attacks=[r.spec for r in selection.restorers + selection.readers],
                    scenes=scenes, profile=p, seeds=_seeds(seeds), device=check_device(device),
                    plate_format=plate_format, frames=frames, budget_s=budget_s,
                    chains=chains, lens_files=lens_files)
    return cfg, selection


def _is_spec_path(name: str) -> bool:
    return name.endswith(".toml") or Path(name).is_file()


def _lens_names(given: list[str]) -> tuple[list[str], dict[str, LensFile]]:
    """The run's lens names and its spec-file lenses, checked before any work: a registered name stays,
    a spec file is known by its spec's `name` (rows, tables, pictures, entries), its task keys by the
    spec's digest (a registered fixed lens's own spec file is that lens, under its name).

    Raises:
        lenses.UnknownLensError: a name neither registered nor a spec file (close names suggested).
        lenses.LensSpecError: a spec file that does not load.
        ValueError: two lenses of the run share a name, or a spec file takes a registered lens's name
            for another lens.
    """
    known = lenses.available()
    names: list[str] = []
    files: dict[str, LensFile] = {}
    sources: dict[str, str] = {}
    for given_name in given:
        if not _is_spec_path(given_name):
            if given_name not in known:
                lenses.load(given_name)  # raises with the close names
            name = given_name
        else:
            spec = lenses.load_spec(given_name)
            name = spec.name
            if name in known:  # the registered lens's own spec file is that lens; another lens is refused
                if not _is_registered_spec(name, known[name], spec):
                    raise ValueError(f"lens spec {given_name!r} is named {name!r}, which is the registered lens "
                                     f"{name!r} ({known[name]}); give the spec another name (its `name` field)")
            else:
                files[name] = LensFile(path=given_name, digest=config_hash(spec.to_dict()))
        if name in sources:
            raise ValueError(f"lenses {sources[name]!r} and {given_name!r} are both named {name!r}; results are "
                             "keyed by the lens name: give each spec its own `name`, or name a lens once")
        sources[name] = given_name
        names.append(name)
    return names, files


def _is_registered_spec(name: str, entry_point: str, spec: lenses.LensSpec) -> bool:
    """Whether `spec` is the registered fixed lens `name` (entry point `entry_point`) itself (its shipped
    spec file, say)."""
    if not entry_point.startswith("lenses.builtin:"):
        return False  # a co-designed or plugin lens: loading it to compare could train it
    return lenses.load(name).spec.to_dict() == spec.to_dict()


def select_attackers(requested: Sequence[AttackerLike] | None, remote: bool, isolate: bool = True
                     ) -> runner.Selection:
    """The run's attackers from names, file specs and attacker objects, in the order given.

    Names go through `runner.select_attackers` (an unknown name is an error, a plugin that fails
    to load a failed row); an object whose constructor raises is a failed row too.

    Raises:
        attacks.DuplicatePluginError: two attackers share a name (results are keyed by it).
        TypeError: an item is neither a str nor an attacker class or instance.
        attacker_objects.AttackerTransportError: `remote` and an object cannot travel.
    """
    if requested is None:
        return runner.select_attackers(None, isolate)
    if isinstance(requested, (str, type, attacks.Attack)):
        requested = [requested]
    for item in requested:
        if not (isinstance(item, str) or attacker_objects.is_attacker_object(item)):
            raise TypeError(f"attacks: {item!r} is neither a name/'file.py:Class' spec nor an attacks.Restorer or "
                            "attacks.Reader class or instance")
    named = [item for item in requested if isinstance(item, str)]
    by_spec: dict[str, AttackerRef] = {}
    failures: list[attacks.PluginFailure] = []
    kinds: dict[str, str] = {}
    if named:
        chosen = runner.select_attackers(named, isolate)
        failures += chosen.failures
        # keyed by the spec as given (an isolated attacker's ref carries it behind sandbox.ISOLATED)
        by_spec.update({r.spec.removeprefix(ISOLATED): r for r in chosen.restorers + chosen.readers})
        kinds.update({r.spec.removeprefix(ISOLATED): "restorer" for r in chosen.restorers})
    restorers: list[AttackerRef] = []
    readers: list[AttackerRef] = []
    sources: dict[str, str] = {}  # attacker name -> where it came from
    for item in requested:
        if isinstance(item, str):
            ref = by_spec.pop(item, None)
            if ref is None:  # failed to load (a failure row already), or named twice (as the CLI allows)
                continue
            is_restorer, origin = kinds.get(item) == "restorer", f"{item!r}"
        else:
            cls = item if isinstance(item, type) else type(item)
            attacker_objects.check(item, remote)  # a misuse raises here
            try:
                ref, attacker = attacker_objects.reference(item, remote)
            except Exception as exc:  # noqa: BLE001 - a constructor that raises is a failed row, as for a plugin
                kind = "reader" if issubclass(cls, attacks.Reader) else "restorer"
                failures.append(attacks.PluginFailure(getattr(cls, "name", cls.__qualname__),
                                                      f"{type(exc).__name__}: {exc}", kind))
                continue
            is_restorer = isinstance(attacker, attacks.Restorer)
            origin = f"{'class' if isinstance(item, type) else 'instance of'} {cls.__module__}.{cls.__qualname__}"
        if ref.name in sources:
            raise attacks.DuplicatePluginError(
                f"attacker name {ref.name!r} is given twice: by {sources[ref.name]} and by {origin}; "
                "rename one of them (results are keyed by the name)")
        sources[ref.name] = origin
        (restorers if is_restorer else readers).append(ref)
    return runner.Selection(restorers, readers, failures)


def prepare_out(path: Path | None) -> tuple[Path, bool]:
    """The output folder (default runs/<date-time>), created and checked writable before any
    compute; and whether it was created now (so a run that fails early can remove it again)."""
    out = path or Path("runs") / _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    if out.exists() and not out.is_dir():
        raise ValueError(f"out {str(out)!r} is a file; give a folder (it is created if missing)")
    created = not out.exists()
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out):
            pass
    except OSError as exc:
        raise ValueError(f"out {str(out)!r} is not a writable folder ({exc.strerror or exc})") from None
    return out, created


def write_run_outputs(out: Path, results: Results) -> None:
    """results.json (schema rows + their settings), tables, pictures and charts of a run."""
    from benchmark.results import run_tables as report
    from benchmark.results.charts.run_charts import write_run_charts
    from benchmark.results.observer.published import write_run_check
    results.write(out / "results.json")
    output = results.output
    assert output is not None, "only a run's own results carry its pictures and plate records"
    for picture in output.pictures:
        copy_picture(picture, out / picture.name, output.picture_key)
    if output.plates:
        report.write_plate_records(out, output.plates)
    write_run_charts(out, results.rows, output.plates, output.bound_curves)
    report.write_tables(out, results.rows)
    write_run_check(out, output.plates, output.lens_info)  # ceiling_check.json; violations logged as ERROR
    log_attack_flags(results.rows, output.lens_info)


def log_attack_flags(rows: list, lens_info: dict) -> list:
    """Log every attack flag of a run's lenses as a WARNING (benchmark.results.attack_gap; the CLI
    prints them) and return them; a lens's spec (`lens_info`) decides whether the study's ceiling applies."""
    from benchmark.results.attack_gap import lens_flags
    from benchmark.results.observer.published import load_study
    study = load_study()
    flags = [f for lens in dict.fromkeys(r.lens for r in rows)
             for f in lens_flags(lens, rows[0].profile, rows, lens_info.get(lens, {}).get("spec"), study)]
    for flag in flags:
        log.warning("attack flag: %s", flag.text())
    return flags


# ---- the dry run ----------------------------------------------------------------------------------

@dataclass(frozen=True)
class PlannedTask:
    """One task of a plan.

    Attributes:
        key: The task's key (its folder in the run's cache).
        kind, seed, lens: What the task is (`benchmark.runner.planning.Task`).
        attackers: Names of the restorers and readers it runs.
        cached: True when its result is in the cache (the run reads it), False when it would be computed.
        recorded_s: For a cached task, the wall time (s) it took when computed, if recorded.
        estimate: Measured cost of this work (`task_costs.Estimate`), from any run in the cache.
    """

    key: str
    kind: str
    seed: int
    lens: str
    attackers: tuple[str, ...]
    cached: bool
    recorded_s: float | None
    estimate: task_costs.Estimate

    @property
    def state(self) -> str:
        return "cached" if self.cached else "compute"


@dataclass
class Plan:
    """The tasks a run would execute, in order, with their cache state and measured cost."""

    tasks: list[PlannedTask]
    directory: Path           # the run's folder in the cache
    profile: str
    failures: list[attacks.PluginFailure] = field(default_factory=list)  # attackers that did not load

    def render(self) -> str:
        """The plan as text: one line per task (key, cached/compute, cost), then a summary."""
        width = max([len(t.key) for t in self.tasks] + [4])
        lines = [f"dry run: {len(self.tasks)} tasks, profile {self.profile}, task results in {self.directory}",
                 f"  {'task':<{width}}  {'state':<8}  cost"]
        for t in self.tasks:
            if t.cached:
                cost = f"{t.recorded_s:.1f} s when computed" if t.recorded_s is not None else "not recorded"
            else:
                cost = t.estimate.text()
            lines.append(f"  {t.key:<{width}}  {t.state:<8}  {cost}")
        todo = [t for t in self.tasks if not t.cached]
        summary = f"{len(self.tasks) - len(todo)} cached, {len(todo)} to compute"
        if todo:
            est = task_costs.total([(t.seed, t.lens, t.estimate) for t in todo])
            counted = len(todo) - est.unknown - est.installed
            summary += (f"; estimated total {est.seconds:.0f} s ({est.seconds / 60:.1f} min) for {counted} of them"
                        if counted else "; no estimate")
            if est.machines:
                summary += ", from task costs measured on " + " and ".join(
                    f"{m}{', ' + d if d else ''}" for m, d in est.machines) + " (load stretches it)"
            if est.installed:
                summary += f"; {est.installed} installed from the package (not measured apart)"
            if est.unknown:
                summary += f"; {est.unknown} unknown"
        lines.append(summary)
        lines += [f"attacker {f.name!r} does not load and would give failed rows: {f.error}" for f in self.failures]
        return "\n".join(lines)

    def table(self) -> pd.DataFrame:
        """The plan as a DataFrame: key, kind, seed, lens, attackers, state, recorded_s, estimate_s, n_measured."""
        import pandas as pd
        return pd.DataFrame.from_records(
            [{"key": t.key, "kind": t.kind, "seed": t.seed, "lens": t.lens, "attackers": ",".join(t.attackers),
              "state": t.state, "recorded_s": t.recorded_s, "estimate_s": t.estimate.seconds,
              "n_measured": t.estimate.n} for t in self.tasks])


def plan(lenses: str | Sequence[str], attacks: Sequence[AttackerLike] | None = None, *,
         profile: str | Profile = "quick", seeds: int | Sequence[int] = (0,), scenes: str = "synthetic",
         device: str = "cpu", executor: str = "local", plate_format: str | None = None,
         frames: int = 30, budget_s: float | None = None, all_chains: bool = False, isolate: bool = True) -> Plan:
    """The dry run of `run` with the same arguments: its tasks, which are cached, what each costs.

    Computes nothing and writes nothing (the attackers are constructed, to know their kinds: with
    `isolate`, a plugin not shipped with the suite in a process of its own).
    A task's cost is the median wall time measured for the same work (kind, lens, attackers,
    profile settings, scenes, device; any seed) in the cache, or unknown.
    """
    if not isinstance(isolate, bool):
        raise TypeError(f"isolate must be True or False, got {isolate!r}")
    cfg, selection = _configure(lenses, attacks, profile, seeds, scenes, device, executor, plate_format, frames,
                                budget_s, all_chains, isolate=isolate)
    directory = run_directory(cfg, selection.restorers, selection.readers)
    measured = task_costs.measurements(cfg.cache_dir)
    kind = None if attacks is not None else "all-chains" if all_chains else "standard"
    planned = []
    for task in plan_tasks(cfg, selection.restorers, selection.readers):
        cached = is_cached(directory, task)
        planned.append(PlannedTask(task.key, task.kind, task.seed, task.lens,
                                   tuple(r.name for r in task.restorers + task.readers), cached,
                                   task_costs.recorded(directory / task.key) if cached else None,
                                   task_costs.estimate(task, cfg, measured, attackers=kind)))
    return Plan(planned, directory, cfg.profile.name, selection.failures)


# ---- argument checks ------------------------------------------------------------------------------

SCENE_SEED_BITS = 62  # a sealed run's scene seeds lie in [0, 2**62): too many to try one by one


def _scene_seeds(seeds: list[int], sealed: bool, given: Mapping[int, int] | None) -> dict[int, int]:
    """The val scene seed of each run seed: `given` (checked), random ones when `sealed`, else none."""
    if not isinstance(sealed, bool):
        raise TypeError(f"sealed must be True or False, got {sealed!r}")
    if given is None:
        return {s: secrets.randbits(SCENE_SEED_BITS) for s in seeds} if sealed else {}
    if sealed:
        raise ValueError("sealed draws new scene seeds and scene_seeds gives them: pass one of the two "
                         "(scene_seeds re-runs a sealed run)")
    chosen = dict(given)
    if set(chosen) != set(seeds):
        raise ValueError(f"scene_seeds must give one scene seed for each run seed {sorted(seeds)}, got "
                         f"{sorted(chosen)}")
    for seed, value in chosen.items():
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < 2 ** 63:
            raise ValueError(f"scene_seeds[{seed}] must be an integer in 0 .. 2**63 - 1, got {value!r}")
    return chosen


def _profile(profile: str | Profile) -> Profile:
    return profile if isinstance(profile, Profile) else get_profile(profile)


# Seeds reach numpy's legacy generators and torch's, which take 0 .. 2**32 - 1 alike.
MAX_SEED = 2**32 - 1


def _seeds(seeds: int | Sequence[int]) -> list[int]:
    if isinstance(seeds, (str, bytes)) or not isinstance(seeds, (int, Sequence)):
        raise TypeError(f"seeds must be an integer or a sequence of integers like [0, 1, 2], got {seeds!r}")
    values = [seeds] if isinstance(seeds, int) else list(seeds)
    if not values or any(isinstance(s, bool) or not isinstance(s, int) for s in values):
        raise ValueError(f"seeds must be one or more integers like [0, 1, 2], got {seeds!r}")
    bad = [s for s in values if not 0 <= s <= MAX_SEED]
    if bad:
        raise ValueError(f"seeds must lie in 0 .. {MAX_SEED} (2**32 - 1), got {bad[0]}")
    if len(set(values)) != len(values):
        raise ValueError(f"seeds lists a seed twice: {seeds!r}")
    return values


def _check_types(**arguments: Any) -> None:
    """TypeError naming the argument, what it got and what it takes, for a wrongly typed argument of
    `run` / `plan` (their values are checked after)."""
    optional = {"plate_format"}
    for name, value in arguments.items():
        if value is None and name in optional:
            continue
        if name == "lens_names":
            items = [value] if isinstance(value, (str, Path)) else value
            if not isinstance(items, (list, tuple)) or not all(isinstance(v, (str, Path)) for v in items):
                raise TypeError(f"lenses must be a lens name or .toml path, or a list of them, got "
                                f"{type(value).__name__} {value!r}")
        elif name == "profile":
            if not isinstance(value, (str, Profile)):
                raise TypeError(f"profile must be a profile name (smoke, quick, paper) or a Profile, got "
                                f"{type(value).__name__} {value!r}")
        elif not isinstance(value, str):
            raise TypeError(f"{name} must be a str{' or None' if name in optional else ''}, got "
                            f"{type(value).__name__} {value!r}")


def _check_meta(meta: Mapping[str, Any] | None) -> None:
    """`meta` is stored in results.json: a mapping with str keys that JSON can write, checked before any compute."""
    import json
    if meta is None:
        return
    if not isinstance(meta, Mapping) or not all(isinstance(k, str) for k in meta):
        raise TypeError(f"meta must be a mapping with str keys (stored in results.json) or None, got "
                        f"{type(meta).__name__} {meta!r}")
    try:
        json.dumps(dict(meta))
    except (TypeError, ValueError) as exc:
        raise TypeError(f"meta must hold only what JSON can store (it goes into results.json): {exc}") from None


def check_device(device: str) -> str:
    """`device` when torch can use it ("cpu", "cuda", "cuda:N"); else ValueError saying what is valid."""
    import torch
    if device == "cpu":
        return device
    if device.startswith("cuda"):
        if not torch.cuda.is_available():
            raise ValueError("device cuda was asked for but torch sees no CUDA device; use device cpu")
        return device
    raise ValueError(f"device must be cpu or cuda[:N], got {device!r}")
