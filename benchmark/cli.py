"""Privacy Lens Bench: push scenes through candidate lenses, attack the sensor images, score
utility against privacy."""

from __future__ import annotations

import argparse
import contextlib
import datetime as _dt
import errno
import logging
import json
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

# Nothing downloads, nothing phones home at run time (common/offline.py says which switches and why).
import common.offline  # noqa: E402,F401

# Everything below imports torch (through lenses, attacks or the stages) only when a command needs it,
# so that `--help` answers at once: tests/benchmark/test_cli_messages.py checks that building the parser
# imports no torch.
EPILOG = """examples:
  python -m benchmark list                                        lenses, attackers, scene sets
  python -m benchmark run --lens ideal --profile smoke            a first look: about a minute
  python -m benchmark run --lens gp --lens defocus --seeds 0,1    the quick profile, two seeds
  python -m benchmark run --lens gp --dry-run                     the task plan, computing nothing
  python -m benchmark run --lens ideal --attack wiener-known-psf --attack lpdr --out runs/first
  python -m benchmark export-mask gp --format zemax-gridsag --out gp_mask.dat
  python -m benchmark report                                      re-render leaderboard/
  python -m benchmark publish --dry-run                           the whole quick leaderboard's plan and cost

`python -m benchmark COMMAND --help` for a command's options."""
MASK_FORMATS = ("npy", "tiff", "zemax-gridsag", "csv")  # lenses.mask_export.FORMATS (a test keeps them equal)
MAX_MASK_SAMPLES = 8193  # 8193^2 float64 = 0.5 GiB per grid; export-mask holds a few of them


class _LazyChoices(Sequence[str]):
    """Choices computed on first use, so that building the parser imports nothing heavy (argparse
    reads them only to check a value or to print that command's help)."""

    def __init__(self, compute: Callable[[], Sequence[str]]) -> None:
        self._compute = compute
        self._values: list[str] | None = None

    def _get(self) -> list[str]:
        if self._values is None:
            self._values = list(self._compute())
        return self._values

    def __getitem__(self, index: Any) -> Any:
        return self._get()[index]

    def __len__(self) -> int:
        return len(self._get())

    def __contains__(self, value: object) -> bool:
        return value in self._get()

    def __iter__(self) -> Iterator[str]:
        return iter(self._get())


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser whose actions may carry ``lazy_help``: a callable that writes their help
    when it is printed (e.g. the attackers that run by default, read from their classes)."""

    def format_help(self) -> str:
        for action in self._actions:
            lazy = getattr(action, "lazy_help", None)
            if lazy is not None:
                action.help = lazy()
        return super().format_help()


def _profile_names() -> list[str]:
    from benchmark.store.profiles import PROFILES
    return list(PROFILES)


PROFILE_CHOICES = _LazyChoices(_profile_names)


MAX_SEED = 2**32 - 1  # benchmark.api.MAX_SEED: numpy's and torch's generators take 0 .. 2**32 - 1


def _seeds(text: str) -> list[int]:
    parts = [s.strip() for s in text.split(",")]
    try:
        seeds = [int(s) for s in parts]
    except ValueError:
        raise argparse.ArgumentTypeError(f"--seeds must be comma-separated integers like 0,1,2, got {text!r}") from None
    if len(set(seeds)) != len(seeds):
        raise argparse.ArgumentTypeError(f"--seeds lists a seed twice: {text!r}")
    bad = [s for s in seeds if not 0 <= s <= MAX_SEED]
    if bad:
        raise argparse.ArgumentTypeError(f"--seeds must lie in 0 .. {MAX_SEED} (2**32 - 1), got {bad[0]}")
    return seeds


def _scene_seeds(text: str) -> dict[int, int]:
    """--scene-seeds RUN=SCENE,...: a sealed run's scene seeds (its results' meta "scene_seeds")."""
    out: dict[int, int] = {}
    for part in text.split(","):
        run_seed, sep, scene_seed = part.strip().partition("=")
        try:
            if not sep:
                raise ValueError
            out[int(run_seed)] = int(scene_seed)
        except ValueError:
            raise argparse.ArgumentTypeError(f"--scene-seeds takes RUN_SEED=SCENE_SEED pairs like 0=12345,1=678 "
                                             f"(a sealed run's meta \"scene_seeds\"), got {part.strip()!r}") from None
    return out


def _plate_format(text: str) -> str:
    if not text or set(text) - {"L", "D"}:
        raise argparse.ArgumentTypeError(f"--plate-format takes L (letter) and D (digit) only, like LLDDDDD, "
                                         f"got {text!r}")
    return text


def _budget(text: str) -> float:
    try:
        seconds = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--budget-s must be a number of seconds, got {text!r}") from None
    if not seconds > 0:
        raise argparse.ArgumentTypeError(f"--budget-s must be > 0 seconds, got {text!r}")
    return seconds


def _device(text: str) -> str:
    from benchmark.api import check_device
    try:
        return check_device(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"--{exc}") from None


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="python -m benchmark", description=__doc__, epilog=EPILOG,
                     formatter_class=argparse.RawDescriptionHelpFormatter)
    loudness = parser.add_mutually_exclusive_group()
    loudness.add_argument("-v", "--verbose", action="store_true", help="log debug messages too")
    loudness.add_argument("-q", "--quiet", action="store_true", help="log warnings and errors only")
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="push scenes through lenses, attack the sensor images, write a table")
    run.add_argument("--lens", action="append", required=True, metavar="NAME|SPEC.toml",
                     help="lens to benchmark (repeatable): a registered name or a .toml spec path")
    attack = run.add_argument("--attack", action="append", default=None, metavar="NAME|FILE.py:Class",
                              help="attacker to run (repeatable); every reader given runs on the sensor image and "
                                   "after every restorer given; default: the standard ensemble (docs/ensemble.md)")
    attack.lazy_help = _attack_help  # type: ignore[attr-defined]
    run.add_argument("--all-chains", action="store_true",
                     help="without --attack: every attacker registered to run by default, every reader after every "
                          "restorer (the full cross product), then the standard ensemble's cascade on the plates none "
                          "of them read, instead of the standard ensemble's chains")
    run.add_argument("--scenes", default="synthetic", help="synthetic (default), photos, or cityscapes:PATH")
    run.add_argument("--profile", default="quick", choices=PROFILE_CHOICES, metavar="PROFILE",
                     help="run size: %(choices)s (default: quick)")
    run.add_argument("--seeds", type=_seeds, default=[0], help="comma-separated seeds, e.g. 0,1,2 (default 0)")
    run.add_argument("--sealed", action="store_true",
                     help="draw the val scenes of each seed from a random seed no attacker is given, written with "
                          "the results after the attackers ran (for plugins not shipped with the suite: one "
                          "cannot rebuild the test scenes beforehand); not publishable")
    run.add_argument("--no-isolate", action="store_true",
                     help="run attackers not shipped with the suite (a file spec, another package's entry point) in "
                          "this process instead of one of their own each (faster to start, for your own plugin under "
                          "development; refused with --sealed)")
    run.add_argument("--scene-seeds", type=_scene_seeds, default=None, metavar="RUN=SCENE,...",
                     help="re-run a sealed run: its scene seeds (results.json meta \"scene_seeds\")")
    run.add_argument("--device", type=_device, default="cpu", help="cpu (default) or cuda[:N]")
    run.add_argument("--out", type=Path, default=None, help="output folder (default runs/<date-time>)")
    run.add_argument("--executor", default="local", metavar="local|ray|ray://HOST:PORT",
                     help="where tasks run: here (default), a local Ray instance, or a Ray cluster")
    run.add_argument("--publish", action="store_true",
                     help="also write one leaderboard entry per lens to leaderboard/entries/ and re-render it")
    run.add_argument("--plate-format", type=_plate_format, default=None, metavar="FORMAT",
                     help="plate strings the privacy bound counts: L = letter, D = digit (default: the scene generator's)")
    run.add_argument("--budget-s", type=_budget, default=None, metavar="SECONDS",
                     help="wall-time budget of each expensive step (a lens's co-design, an attacker's fit, restore "
                          "or read; the bound): "
                          "a step past it gives a failed row with a clear message (default: none). It is checked "
                          "between Python operations (a signal), so one long native call (a big convolution, an "
                          "ONNX Runtime run) finishes first: a step can overrun it by that call's length")
    run.add_argument("--frames", type=int, default=30, metavar="T",
                     help="frames of a static plate for the video bound (default 30; T = 1 is always reported)")
    run.add_argument("--dry-run", action="store_true",
                     help="print the task plan (cached or to compute, measured cost per task) and compute nothing")
    run.add_argument("--profile-time", action="store_true",
                     help="profile every computed task (cProfile, peak memory): profile.json and profile.md in --out")
    run.add_argument("--profile-python-memory", action="store_true",
                     help="with --profile-time, also trace Python/NumPy allocations (tracemalloc: Python-heavy code "
                          "such as a co-design step runs ~1.3x slower)")
    train = sub.add_parser("train", help="train (or load) a co-designed lens; under torchrun, data-parallel over the ranks")
    train.add_argument("--lens", required=True, choices=CODESIGN_CHOICES, metavar="LENS", help="co-design scheme registered as a lens: %(choices)s")
    train.add_argument("--profile", default="quick", choices=PROFILE_CHOICES, metavar="PROFILE",
                     help="run size: %(choices)s (default: quick)")
    train.add_argument("--seed", type=int, default=0, help="training seed (default 0)")
    train.add_argument("--device", type=_device, default="cpu",
                       help="cpu (default; gloo under torchrun) or cuda (NCCL under torchrun, one GPU per rank)")
    pre = sub.add_parser("pretrain", help="pre-train the clean utility net to its plateau; export weights + provenance")
    pre.add_argument("--profile", default="quick", choices=PROFILE_CHOICES, metavar="PROFILE",
                     help="recipe and val set: %(choices)s (default: quick)")
    pre.add_argument("--seed", type=int, default=0, help="training seed, and the seed of the val scenes (default 0)")
    pre.add_argument("--out", type=Path, default=None,
                     help="weights folder (default: the package's benchmark/codesign/utility/weights)")
    pre.add_argument("--dir", type=Path, default=None,
                     help="leaderboard folder for the study and chart (default: the repository's)")
    pre.add_argument("--device", type=_device, default="cpu", help="cpu (default) or cuda[:N]")
    ship = sub.add_parser("pretrain-attacker", help="train (or load from the cache) a lens-independent attacker "
                                                    "and ship its weights in the package with their provenance")
    ship.add_argument("attacker", choices=["nafnet-generic", "learned-reader", "nafnet-known-psf", "learned-reader-psf"],
                      help="the lens-independent attacker (learned-reader: its pre-training on sharp plates; "
                           "nafnet-known-psf, learned-reader-psf: their pre-trainings across the lens family, "
                           "resumable)")
    ship.add_argument("--profile", default="quick", choices=PROFILE_CHOICES, metavar="PROFILE",
                     help="budget: %(choices)s (default: quick)")
    ship.add_argument("--seed", type=int, default=0, help="training seed (default 0)")
    ship.add_argument("--family", action="store_true",
                      help="learned-reader only: its pre-training across the lens family, from the sharp start "
                           "(resumable: the checkpoint is in the cache; run the command again to continue)")
    ship.add_argument("--out", type=Path, default=None, help="weights folder (default: the package's attacks/weights)")
    pub = sub.add_parser("publish", help="re-publish the leaderboard in one resumable run: every registered lens "
                                         "(or those named) at the profile's seeds, the standard ensemble")
    pub.add_argument("--lens", action="append", default=None, metavar="NAME",
                     help="lens to re-publish (repeatable; default: every registered lens)")
    pub.add_argument("--profile", default="quick", choices=PROFILE_CHOICES, metavar="PROFILE",
                     help="run size: %(choices)s (default: quick)")
    pub.add_argument("--seeds", type=_seeds, default=[0, 1, 2], help="comma-separated seeds (default 0,1,2)")
    pub.add_argument("--device", type=_device, default="cpu", help="cpu (default) or cuda[:N]")
    pub.add_argument("--out", type=Path, default=None,
                     help="the run's folder (default runs/publish-<profile>); the same command resumes there")
    pub.add_argument("--dir", type=Path, default=None, help="leaderboard folder (default: the repository's)")
    pub.add_argument("--dry-run", action="store_true", help="print the plan and its estimated cost; compute nothing")
    pub.add_argument("--compute-only", action="store_true",
                     help="compute and cache the run's tasks, publish nothing (what each process of a publish "
                          "runs; a plain publish runs one per lens and seed)")
    lens_ship = sub.add_parser("ship-lens", help="co-design (or load from the cache) a lens and ship it, with its "
                                                 "known-pairs NAFNet and learned reader, in the package with their provenance")
    lens_ship.add_argument("lens", choices=CODESIGN_CHOICES, metavar="LENS",
                           help="co-design scheme registered as a lens: %(choices)s")
    lens_ship.add_argument("--profile", default="quick", choices=PROFILE_CHOICES, metavar="PROFILE",
                     help="run size: %(choices)s (default: quick)")
    lens_ship.add_argument("--seed", type=int, default=0, help="training seed (default 0)")
    lens_ship.add_argument("--out", type=Path, default=None,
                           help="folder to write into instead of the package (the lens there, the attacker's "
                                "weights in OUT/attack_weights)")
    lens_ship.add_argument("--reader-only", action="store_true",
                           help="ship only the learned reader's fit on the lens a run loads (the shipped one), "
                                "leaving the shipped lens and NAFNet as they are")
    listing = sub.add_parser("list", help="list lenses and attackers (what each is, its threat model, whether it runs "
                                          "by default) and scene sets")
    listing.add_argument("--json", action="store_true", help="print one JSON object, for scripts")
    rep = sub.add_parser("report", help="render leaderboard/README.md and charts from leaderboard/entries/")
    rep.add_argument("--dir", type=Path, default=None, help="leaderboard folder (default: the repository's)")
    rep.add_argument("--migrate", action="store_true",
                     help="first rewrite stored entries of an older format in the current one "
                          "(leaderboard_entries.ENTRY_VERSION)")
    rep.add_argument("--publish", type=Path, action="append", default=[], metavar="RUN_DIR",
                     help="first publish a finished run from its folder (its results.json), as `run --publish` "
                          "would have; repeatable")
    mask = sub.add_parser("export-mask", help="write a lens's phase mask as a height map (um) a fab or Zemax can read")
    mask.add_argument("lens", metavar="LENS",
                      help="registered lens name, a .toml spec, or a leaderboard entry .json (its published mask)")
    mask.add_argument("--format", required=True, choices=list(MASK_FORMATS), dest="fmt",
                      help="npy (float64), tiff (32-bit float), zemax-gridsag (OpticStudio Grid Sag .DAT, mm), "
                           "csv (x_mm, y_mm, height_um); metadata in PATH.json beside it")
    mask.add_argument("--out", type=Path, required=True, metavar="PATH", help="file to write")
    mask.add_argument("--samples", type=int, default=257,
                      help=f"grid nodes per side across the aperture, 5 .. {MAX_MASK_SAMPLES} (default 257)")
    mask.add_argument("--profile", default="quick", choices=PROFILE_CHOICES, metavar="PROFILE",
                      help="a co-designed lens's training profile: %(choices)s (default: quick)")
    mask.add_argument("--seed", type=int, default=0, help="a co-designed lens's training seed (default 0)")
    mask.add_argument("--train", action="store_true",
                      help="co-design the lens first when neither the cache nor the package holds it "
                           "(minutes; without it such a lens is refused)")
    study = sub.add_parser("study", help="measure a modelling-choice study into leaderboard/studies/ and re-render")
    study.add_argument("name", choices=["psf-grid", "utility-size"],
                       help="psf-grid: PSF support, pupil grid, oversampling vs error and time; "
                            "utility-size: SegFormer variants, each trained to its plateau, vs mIoU")
    study.add_argument("--profile", default="quick", choices=PROFILE_CHOICES, metavar="PROFILE",
                     help="utility-size's budget: %(choices)s (default: quick)")
    study.add_argument("--variants", default=None, metavar="V1,V2,...",
                       help="utility-size's SegFormer variants, smallest first, the suite's last (default: "
                            "tiny,b0-narrow,b0); MODEL@PX trains MODEL on PX x PX crops, e.g. tiny@256")
    study.add_argument("--dir", type=Path, default=None, help="leaderboard folder (default: the repository's)")
    return parser


def _codesign_lenses() -> list[str]:
    from benchmark.codesign.schemes import SCHEMES
    return [name for name, scheme in SCHEMES.items() if scheme.optics]  # "fixed" is no registered lens


CODESIGN_CHOICES = _LazyChoices(_codesign_lenses)


def _attack_help() -> str:
    """`run --attack`'s help: the standard ensemble's chains, what --all-chains adds (the attackers
    that run by default, read from their classes), and what runs only when named."""
    from benchmark.runner.defaults import CASCADE, STANDARD_ENSEMBLE
    rows = attacker_catalogue()
    default = [r["name"] for r in rows if r["runs_by_default"]]
    named = [r["name"] for r in rows if not r["runs_by_default"] and not r["standard_chains"]]
    text = ("attacker to run (repeatable): a registered name or FILE.py:Class; every reader given runs on the "
            "sensor image and after every restorer given; default: the standard ensemble's chains ("
            + ", ".join(STANDARD_ENSEMBLE) + "); with --all-chains: " + (", ".join(default) if default else "none")
            + ", every reader after every restorer, then the cascade " + ", ".join(CASCADE))
    if named:
        text += "; run only when named: " + ", ".join(named)
    return text.replace("%", "%%")


def _first_line(text: str | None) -> str:
    """A docstring's first paragraph on one line (its summary)."""
    paragraph = (text or "").strip().split("\n\n")[0]
    return " ".join(paragraph.split())


def attacker_catalogue() -> list[dict[str, Any]]:
    """Every registered attacker: name, kind (restorer/reader), threat model, whether it runs by
    default, a one-line description and where it comes from; one that fails to import says why."""
    import attacks
    from attacks.registry import ATTACKS_GROUP
    from benchmark.runner.defaults import STANDARD_ENSEMBLE, chain_parts
    from common.plugins import discover
    rows = []
    for name, entry in sorted(discover(ATTACKS_GROUP).items()):
        row: dict[str, Any] = {"name": name, "source": entry.value,
                               "standard_chains": [c for c in STANDARD_ENSEMBLE if name in chain_parts(c)]}
        try:
            cls = entry.load()
            row.update(kind="reader" if issubclass(cls, attacks.Reader) else "restorer",
                       threat_model=cls.threat_model.value, runs_by_default=bool(cls.run_by_default),
                       reference=bool(getattr(cls, "reference", False)), description=_first_line(cls.__doc__))
        except Exception as exc:  # noqa: BLE001 - a broken plugin is listed, not fatal
            row.update(kind=None, threat_model=None, runs_by_default=False, reference=False,
                       description=f"fails to load: {type(exc).__name__}: {exc}")
        rows.append(row)
    return rows


def lens_catalogue() -> list[dict[str, Any]]:
    """Every registered lens: name, whether it is co-designed (trained per profile and seed) or
    fixed, a one-line description and where it comes from. Lenses run only when named (--lens)."""
    import lenses
    from benchmark.codesign.schemes import SCHEMES
    from common.plugins import discover
    rows = []
    for name, entry in sorted(discover(lenses.GROUP).items()):
        scheme = SCHEMES.get(name)
        try:
            description = _first_line(entry.load().__doc__)
        except Exception as exc:  # noqa: BLE001 - a broken plugin is listed, not fatal
            description = f"fails to load: {type(exc).__name__}: {exc}"
        if scheme is not None and entry.value.startswith("benchmark.codesign."):
            description = description or scheme.description
        rows.append({"name": name, "kind": "co-designed" if scheme is not None else "fixed",
                     "description": description, "source": entry.value})
    return rows


def cmd_train(args: argparse.Namespace) -> int:
    from benchmark.store.cache import cache_root
    from benchmark.store.profiles import get_profile
    from benchmark.codesign.codesigned_lenses import START_SPEC
    from benchmark.codesign.distributed import session
    from benchmark.codesign.schemes import SCHEMES
    from benchmark.codesign.trainer import CoDesign
    from lenses.spec import load_spec

    with session(args.device) as (replicas, device):
        run = CoDesign(load_spec(START_SPEC), SCHEMES[args.lens], get_profile(args.profile), args.seed, device,
                       cache_root(), replicas=replicas)
        trained = run.load_or_train()
        if replicas is None or replicas.is_writer:
            record = trained.record
            print(f"{args.lens}: artifacts in {trained.directory} (trained on {record.get('world_size', 1)} "
                  f"process(es), {record['seconds_per_step'] or 0:.3f} s/step)")
            print("final coefficients (um, Noll Z1..Z6): "
                  + ", ".join(f"{c:+.5f}" for c in record["final_coefficients_um"]))
    return 0


def lens_kind_catalogue() -> list[dict[str, str]]:
    """Every kind of lens spec a .toml file may give (--lens FILE.toml): its name, what it holds, an example."""
    from lenses.builtin import EXAMPLES
    from lenses.spec import KIND_DESCRIPTIONS
    rows = []
    for kind, description in KIND_DESCRIPTIONS.items():
        example = EXAMPLES[kind]
        try:
            shown = str(example.relative_to(Path.cwd()))
        except ValueError:  # run from elsewhere: the installed path
            shown = str(example)
        rows.append({"kind": kind, "description": description, "example": shown})
    return rows


def cmd_list(args: argparse.Namespace) -> int:
    from benchmark.scenes import SCENE_SETS
    lens_rows, attacker_rows, kind_rows = lens_catalogue(), attacker_catalogue(), lens_kind_catalogue()
    if args.json:
        print(json.dumps({"lenses": lens_rows, "lens_kinds": kind_rows, "attackers": attacker_rows,
                          "scene_sets": [{"name": k, "description": v} for k, v in SCENE_SETS.items()]}, indent=1))
        return 0
    print("lenses (each runs when named: --lens NAME):")
    for row in lens_rows:
        print(f"  {row['name']:16s} {row['kind']:12s} {row['description']}")
    print("lens spec kinds (bring your own lens: --lens FILE.toml; README, docs/lenses.md):")
    for row in kind_rows:
        print(f"  {row['kind']:16s} {row['description']}; example: {row['example']}")
    print("attackers (standard: in the standard ensemble, run when --attack is not given (docs/ensemble.md); "
          "all-chains: added by --all-chains; named: only with --attack NAME):")
    for row in attacker_rows:
        when = "standard" if row["standard_chains"] else "all-chains" if row["runs_by_default"] else "named"
        print(f"  {row['name']:26s} {row['kind'] or '?':9s} {row['threat_model'] or '?':18s} {when:10s} "
              f"{row['description']}")
    print("scene sets:")
    for name, text in SCENE_SETS.items():
        print(f"  {name:16s} {text}")
    return 0


def cmd_run(args: argparse.Namespace) -> int:
    from benchmark import api
    from benchmark.runner.diagnostics import profiling
    from benchmark.store.profiles import get_profile

    options = dict(lenses=args.lens, attacks=args.attack, profile=args.profile, seeds=args.seeds,
                   scenes=args.scenes, device=args.device, executor=args.executor,
                   plate_format=args.plate_format, frames=args.frames, budget_s=args.budget_s,
                   all_chains=args.all_chains, isolate=not args.no_isolate)
    if args.dry_run:
        print(api.plan(**options).render())
        return 0
    out = args.out or Path("runs") / _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    started = time.time() - 1.0  # file times may be coarse: a file written from now on is this run's
    profiled = (profiling.profiled(out, get_profile(args.profile).n_val, args.device, args.executor,
                                   trace_python=args.profile_python_memory)
                if args.profile_time else contextlib.nullcontext())
    with profiled:
        results = api.run(**options, out=out, meta={"command": sys.argv}, sealed=args.sealed,
                          scene_seeds=args.scene_seeds)
    print((out / "table.md").read_text())
    if args.publish:
        from benchmark.publish import leaderboard
        output = results.output
        paths = leaderboard.publish_run(output.rows, get_profile(args.profile).to_dict(), output.lens_info, out,
                                        settings=output.settings)
        print(f"published {len(paths)} leaderboard entries; rendered the leaderboard")
    print(f"wrote {out}/: {', '.join(files_written(out, started))} ({results.meta['wall_s']:.1f} s)")
    return report_failures(results.failed)


def cmd_publish(args: argparse.Namespace) -> int:
    """`publish`: plan; compute each lens-seed in a process of its own (a bar over its estimated seconds,
    its time and peak memory logged); assemble every lens from the cache and replace the entries."""
    import lenses
    from benchmark import api
    from benchmark.publish import leaderboard, republish
    from benchmark.store.profiles import get_profile
    from benchmark.store.provenance import code_version

    names = args.lens or sorted(lenses.available())
    options = dict(lenses=names, profile=args.profile, seeds=args.seeds, device=args.device)
    plan = api.plan(**options)
    weights = republish.task_weights(plan.tasks)
    print(f"publish {', '.join(names)} ({args.profile}, seeds {','.join(map(str, args.seeds))}): "
          + republish.summary(plan.tasks, weights))
    if args.dry_run:
        print(plan.render())
        return 0
    out = args.out or Path("runs") / f"publish-{args.profile}"

    def run_with_bar(task_weights: republish.Weights, desc: str) -> Any:
        bar = republish.EtaBar(task_weights, desc=desc)
        try:
            return api.run(**options, out=out, meta={"command": sys.argv, "publish": True}, on_task=bar)
        finally:
            bar.close()

    if args.compute_only:
        return report_failures(run_with_bar(weights, f"publish {', '.join(names)}").failed)
    version = code_version()
    parts = republish.lens_seed_parts(plan.tasks, names, args.seeds, weights)
    ran = republish.lens_processes(parts, args.profile, args.device, out, version)
    died = [p for p in ran if p.died]
    if died:
        d = died[0]
        print(f"error: the process of lens {d.lens} seed {d.seed} died (exit status {d.returncode}) after "
              f"{d.wall_s:.0f} s, at a peak of {d.peak_rss_mib / 1024:.2f} GiB; the tasks it finished are "
              f"cached: run the same command again to resume", file=sys.stderr)
        return 2
    t0 = time.perf_counter()  # every task is in the cache now: the bar's weights are planned again
    results = run_with_bar(republish.task_weights(api.plan(**options).tasks), "assemble")
    output = results.output
    paths = leaderboard.publish_run(output.rows, get_profile(args.profile).to_dict(), output.lens_info, out,
                                    args.dir or leaderboard.LEADERBOARD, settings=output.settings, replace=True)
    print(f"published {len(paths)} leaderboard entries (replacing the older ones whole) and rendered the leaderboard; "
          f"assembled in {(time.perf_counter() - t0) / 60:.1f} min; the run is in {out}/")
    print("compute of this version (publish_log.jsonl): "
          + republish.log_summary(republish.read_log(out, version)))
    return report_failures(results.failed)


def files_written(folder: Path, since: float) -> list[str]:
    """The files under `folder` written at or after `since` (a time.time()), relative, sorted."""
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file() and p.stat().st_mtime >= since)


def report_failures(failed: list) -> int:
    """Print what failed (attacker, stage, message, where) and return the exit status: 0 when
    nothing failed, 1 otherwise (the other rows are written all the same)."""
    if not failed:
        return 0
    print(f"error: {len(failed)} row(s) failed:", file=sys.stderr)
    for row in failed:
        e = row.error
        print(f"  {row.lens} / {row.attack} / seed {row.seed}: {e.attacker} failed at {e.stage}: {e.message}",
              file=sys.stderr)
    return 1


def cmd_report(args: argparse.Namespace) -> int:
    from benchmark.results import entries as leaderboard_entries
    from benchmark.publish import report as leaderboard_report
    directory = args.dir or leaderboard_entries.LEADERBOARD
    if not (directory / "entries").is_dir():
        raise ValueError(f"no leaderboard entries in {directory / 'entries'}; publish some with "
                         "`python -m benchmark run --lens NAME --publish`")
    if args.publish:
        from benchmark.publish import leaderboard
        for run in args.publish:
            for path in leaderboard.publish_results(run, directory):
                print(f"published {path} from {run}")
    if args.migrate:
        for path in leaderboard_entries.migrate_directory(directory):
            print(f"migrated {path} to entry format {leaderboard_entries.ENTRY_VERSION}")
    for path in leaderboard_report.render(directory):
        print(f"wrote {path}")
    if args.dir is None and leaderboard_report.update_readme(leaderboard_entries.LEADERBOARD.parent / "README.md"):
        print("updated the results table of README.md")
    return 0


def cmd_study(args: argparse.Namespace) -> int:
    from benchmark.results import entries as leaderboard_entries
    from benchmark.publish import report as leaderboard_report
    from benchmark.store.profiles import get_profile
    from benchmark.runner.sensing import to_tensor
    from benchmark.scenes.loading import load_scene
    from benchmark.studies import psf_grid, utility_size
    directory = args.dir or leaderboard_entries.LEADERBOARD
    t0 = time.perf_counter()
    if args.name == "psf-grid":
        scene = to_tensor([load_scene("synthetic", "val", 0, (256, 512), 0)])
        path = psf_grid.run(directory / "studies" / "psf_grid.json", scene)
    else:
        variants = tuple(args.variants.split(",")) if args.variants else utility_size.VARIANTS
        path = utility_size.run(directory / "studies" / "utility_size.json", get_profile(args.profile), variants=variants)
    print(f"wrote {path} ({time.perf_counter() - t0:.0f} s)")
    for written in leaderboard_report.render(directory):
        print(f"wrote {written}")
    return 0


def mask_spec(name: str, profile: str, seed: int, train: bool = False):
    """The LensSpec behind `name`: a leaderboard entry .json (its published lens spec), a .toml
    spec, or a registered lens with its current coefficients. A co-designed one is taken from the
    cache (or the package's shipped copy) for `profile` and `seed`; one held by neither is trained
    only with `train` (else a LookupError says how to get it)."""
    import lenses
    from benchmark.store.profiles import get_profile
    if name.endswith(".json"):
        path = Path(name)
        if not path.is_file():
            raise FileNotFoundError(f"leaderboard entry {name!r} does not exist")
        try:
            entry = json.loads(path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise ValueError(f"{name} is not a leaderboard entry: not JSON ({exc})") from None
        if not isinstance(entry, dict):
            raise ValueError(f"{name} is not a leaderboard entry: it holds a JSON {type(entry).__name__}, "
                             "not an object with a lens_spec")
        spec = entry.get("lens_spec")
        if not spec:
            raise ValueError(f"{name}: the entry stores no lens_spec to export")
        return lenses.parse_spec(spec, source=name)
    if not train and name in lenses.available():
        from benchmark.codesign.codesigned_lenses import trained_run
        if trained_run(name, get_profile(profile), seed) is False:
            raise LookupError(f"co-designed lens {name!r} (profile {profile}, seed {seed}) is neither in the cache nor "
                              "shipped; co-designing it takes minutes: pass --train to do it now, run "
                              f"`python -m benchmark run --lens {name} --seed {seed}` first, or export a leaderboard "
                              "entry's published mask (its .json)")
    return lenses.load(name, profile=get_profile(profile), seed=seed).current_spec()


def cmd_export_mask(args: argparse.Namespace) -> int:
    from lenses.mask_export import height_map, write_height_map
    if args.samples > MAX_MASK_SAMPLES:  # before any work: 100000 would ask for 74.5 GiB per grid
        raise ValueError(f"--samples must lie in 5 .. {MAX_MASK_SAMPLES} grid nodes per side, got {args.samples} "
                         f"({args.samples ** 2 * 8 / 2**30:.1f} GiB per {args.samples} x {args.samples} float64 grid)")
    if args.out.is_dir():
        raise ValueError(f"--out {str(args.out)!r} is a folder; give the file to write, e.g. "
                         f"{args.out / ('mask.' + args.fmt.replace('zemax-gridsag', 'dat'))}")
    spec = mask_spec(args.lens, args.profile, args.seed, args.train)
    heights = height_map(spec, args.samples)
    written = write_height_map(heights, args.out, args.fmt)
    meta = heights.metadata
    print(f"{spec.name}: {args.samples} x {args.samples} nodes over {meta['aperture_diameter_mm']} mm "
          f"({meta['grid']['spacing_um']:.3f} um apart), peak-to-valley {meta['peak_to_valley_um']:.4f} um of "
          f"{meta['material']}; wrote {', '.join(str(p) for p in written)}")
    return 0


def cmd_pretrain_attacker(args: argparse.Namespace) -> int:
    from benchmark.publish.ship_attacker import main as ship_main
    return ship_main(args=args)


def cmd_ship_lens(args: argparse.Namespace) -> int:
    from benchmark.publish.ship_lens import main as ship_main
    return ship_main(args=args)


def cmd_pretrain(args: argparse.Namespace) -> int:
    from benchmark.codesign.utility.pretrain import main as pretrain_main
    return pretrain_main(args=args)


def main(argv: list[str] | None = None) -> int:
    from benchmark.runner.diagnostics.known_warnings import silence_known_warnings
    silence_known_warnings()
    parser = build_parser()
    args = parser.parse_args(argv)
    from common.plugins import DuplicateNameError  # imports torch: after --help has answered
    if args.command == "run" and args.profile_python_memory and not args.profile_time:
        parser.error("--profile-python-memory traces allocations inside --profile-time's profile; add --profile-time")
    if args.command == "run" and args.all_chains and args.attack:
        parser.error("--all-chains widens the default attackers; with --attack the run is exactly the attackers "
                     "named (every reader after every restorer): drop one of them")
    if args.command == "run" and args.sealed and args.no_isolate:
        parser.error("--sealed isolates its plugins (it is the run for plugins not shipped with the suite); "
                     "drop --no-isolate")
    if args.command == "run" and (args.sealed or args.scene_seeds) and (args.publish or args.dry_run):
        parser.error(("--sealed" if args.sealed else "--scene-seeds") + " runs scenes other than the seeds' own: "
                     + ("a leaderboard entry is reproduced from its seeds, so it cannot be published (--publish)"
                        if args.publish else "no task of it is cached, there is nothing to plan (--dry-run)"))
    if args.command == "run" and args.dry_run and (args.profile_time or args.publish):
        parser.error("--dry-run computes nothing, so there is nothing to " +
                     ("profile (--profile-time)" if args.profile_time else "publish (--publish)") + "; drop one of them")
    level = logging.DEBUG if args.verbose else logging.WARNING if args.quiet else logging.INFO
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s", force=True)
    commands = {"list": cmd_list, "run": cmd_run, "report": cmd_report, "train": cmd_train, "study": cmd_study,
                "export-mask": cmd_export_mask, "pretrain": cmd_pretrain,
                "pretrain-attacker": cmd_pretrain_attacker, "ship-lens": cmd_ship_lens, "publish": cmd_publish}
    try:
        return commands[args.command](args)
    except (ValueError, LookupError, NotImplementedError, FileNotFoundError, DuplicateNameError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # a full disk, a read-only or another user's folder: a sentence naming the path
        print(f"error: {os_error_message(exc)}", file=sys.stderr)
        return 2


def os_error_message(exc: OSError) -> str:
    """One sentence for an OSError: the path, what went wrong, and what to do about it."""
    path = exc.filename if exc.filename is not None else "a file"
    reason = exc.strerror or str(exc)
    hint = {errno.ENOSPC: "the disk is full; free some space or write elsewhere (--out, PLB_CACHE)",
            errno.EDQUOT: "the disk quota is used up; free some space or write elsewhere (--out, PLB_CACHE)",
            errno.EROFS: "the file system is read-only; write elsewhere (--out, PLB_CACHE)",
            errno.EACCES: "you may not write there (another user's folder?); write elsewhere (--out, PLB_CACHE "
                          "for the cache)",
            errno.EPERM: "you may not write there (another user's folder?); write elsewhere (--out, PLB_CACHE "
                         "for the cache)",
            errno.EISDIR: "it is a folder; give a file path",
            errno.ENOTDIR: "a part of that path is a file, not a folder"}.get(exc.errno or 0, "")
    return f"cannot use {path}: {reason}" + (f"; {hint}" if hint else "")
