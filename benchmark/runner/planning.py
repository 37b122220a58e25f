"""Which tasks a run needs, in an order that respects their dependencies.

Tasks per seed: `clean-utility` (the shared clean segmentation net), `spectrum` (plate spectrum
of the bound), `sharp` (reference rows on the sharp scenes); per lens and seed: `lens` (train or
load it; lens row), `utility`, `bound`, `fit` (one per restorer: train or load it), and `evaluate`
(restore with every restorer, read with every reader on the sensor image and on each restored
image, sample pictures). A task is keyed by the attackers' names, never by how they were given
(a registered name or a file path), so a file plugin is cached and found like an entry point.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from benchmark.store.cache import config_hash
from benchmark.store.provenance import code_version
from benchmark.runner.config import RunConfig
from benchmark.runner.sandbox.proxies import ISOLATED

TASK_VERSION = 2


@dataclass(frozen=True)
class AttackerRef:
    """An attacker of the run: its name (what rows and keys use) and how to load it
    (`benchmark.runner.attacker_objects.load`: a registered name, a file spec, or an object's spec).

    `settings_key` is set for attackers given as Python objects (`benchmark.run`): a hash of their
    `describe()` and source, so that the run's cache tells two instances' options apart."""

    name: str
    spec: str
    settings_key: str = ""

    @property
    def identity(self) -> str:
        """What keys the run's cache: the name, the settings key of an attacker given as an object, and
        whether it runs isolated (results computed with a plugin in the runner's process are not reused)."""
        name = f"{ISOLATED}{self.name}" if self.spec.startswith(ISOLATED) else self.name
        return f"{name}@{self.settings_key}" if self.settings_key else name


@dataclass(frozen=True)
class Task:
    """One unit of work; its result is an artifact addressed by `key`.

    Attributes:
        kind: clean-utility, spectrum, sharp, lens, utility, bound, fit or evaluate.
        seed: The run seed.
        lens: Lens name (empty for per-seed tasks).
        lens_tag: For a lens read from a spec file, a digest of the spec (`RunConfig.lens_tag`): in the key.
        restorers: Restorers the task runs (one for `fit`).
        readers: Readers the task runs.
        deps: Keys of the tasks whose artifacts it needs.
        cpus, gpus: What the task asks a cluster scheduler for.
    """

    kind: str
    seed: int
    lens: str = ""
    restorers: tuple[AttackerRef, ...] = ()
    lens_tag: str = ""
    readers: tuple[AttackerRef, ...] = ()
    deps: tuple[str, ...] = ()
    cpus: float = 1.0
    gpus: float = 0.0

    @property
    def key(self) -> str:
        """File-name-safe identity: kind, seed, lens (with its spec's digest) and, for a fit, the restorer's
        name."""
        parts = [self.kind, f"s{self.seed}", self.lens, self.lens_tag,
                 *(r.name for r in self.restorers if self.kind == "fit")]
        text = "_".join(p for p in parts if p)
        return "".join(c if c.isalnum() or c in "-_." else "-" for c in text)


def fit_task(seed: int, lens: str, restorer: AttackerRef, deps: tuple[str, ...] = (), gpus: float = 0.0,
             lens_tag: str = "") -> Task:
    """The task that fits `restorer` on `lens` (its key is what the evaluate task looks up)."""
    return Task("fit", seed, lens, restorers=(restorer,), deps=deps, cpus=2, gpus=gpus, lens_tag=lens_tag)


def run_directory(cfg: RunConfig, restorers: list[AttackerRef], readers: list[AttackerRef]) -> Path:
    """Where a run's task results live: one folder per (configuration, code version). The lenses and
    seeds are not part of it: each task's key names its own lens and seed (``Task.key``), so a run that
    adds a lens or a seed finds the tasks of the ones already computed. The code version
    (``benchmark.store.provenance.code_version``) changes with any file the results depend on, not
    with docs or tests, so an interrupted run resumes after such a commit; each row still carries the
    commit of the process that computed it. A sealed run's scene seeds are part of it (its tasks are
    its own)."""
    key = config_hash({"version": TASK_VERSION, "code": code_version(),
                       "restorers": [r.identity for r in restorers], "readers": [r.identity for r in readers],
                       "scenes": cfg.scenes, "profile": cfg.profile.to_dict(),
                       "device": cfg.device, "plate_format": cfg.plate_format, "frames": cfg.frames,
                       **({"chains": list(cfg.chains)} if cfg.chains is not None else {}),
                       **({"scene_seeds": {str(k): v for k, v in sorted(cfg.scene_seeds.items())}}
                          if cfg.scene_seeds else {})})
    return Path(cfg.cache_dir) / "tasks" / key


def plan(cfg: RunConfig, restorers: list[AttackerRef], readers: list[AttackerRef]) -> list[Task]:
    """Tasks in an order that respects their dependencies."""
    gpu = 1.0 if cfg.device.startswith("cuda") else 0.0
    tasks: list[Task] = []
    for seed in cfg.seeds:
        clean = Task("clean-utility", seed, cpus=2, gpus=gpu)
        spectrum = Task("spectrum", seed)
        tasks += [clean, spectrum, Task("sharp", seed, readers=tuple(readers), deps=(clean.key,), gpus=gpu)]
        for lens in cfg.lenses:
            tag = cfg.lens_tag(lens)
            t_lens = Task("lens", seed, lens, deps=(clean.key,), cpus=2, gpus=gpu, lens_tag=tag)
            t_util = Task("utility", seed, lens, deps=(t_lens.key, clean.key), cpus=2, gpus=gpu, lens_tag=tag)
            t_bound = Task("bound", seed, lens, deps=(t_lens.key, spectrum.key), lens_tag=tag)
            fits = [fit_task(seed, lens, r, (t_lens.key,), gpu, lens_tag=tag) for r in restorers]
            t_eval = Task("evaluate", seed, lens, restorers=tuple(restorers), readers=tuple(readers),
                          deps=(t_lens.key, t_util.key, *(f.key for f in fits)), cpus=2, gpus=gpu, lens_tag=tag)
            tasks += [t_lens, t_util, t_bound, *fits, t_eval]
    return tasks
