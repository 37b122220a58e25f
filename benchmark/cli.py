"""Command line: `python -m benchmark run ...` and `python -m benchmark list`."""

from __future__ import annotations

import argparse
import datetime as _dt
import logging
import os
import shutil
import sys
import time
from pathlib import Path

# Nothing downloads at run time: guard the libraries that might try.
for _var in ("HF_HUB_OFFLINE", "TRANSFORMERS_OFFLINE", "HF_DATASETS_OFFLINE"):
    os.environ.setdefault(_var, "1")


def _seeds(text: str) -> list[int]:
    parts = [s.strip() for s in text.split(",")]
    try:
        seeds = [int(s) for s in parts]
    except ValueError:
        raise argparse.ArgumentTypeError(f"--seeds must be comma-separated integers like 0,1,2, got {text!r}") from None
    if len(set(seeds)) != len(seeds):
        raise argparse.ArgumentTypeError(f"--seeds lists a seed twice: {text!r}")
    return seeds


def _budget(text: str) -> float:
    try:
        seconds = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--budget-s must be a number of seconds, got {text!r}") from None
    if not seconds > 0:
        raise argparse.ArgumentTypeError(f"--budget-s must be > 0 seconds, got {text!r}")
    return seconds


def _device(text: str) -> str:
    import torch
    if text == "cpu":
        return text
    if text.startswith("cuda"):
        if not torch.cuda.is_available():
            raise argparse.ArgumentTypeError("--device cuda was asked for but torch sees no CUDA device; use --device cpu")
        return text
    raise argparse.ArgumentTypeError(f"--device must be cpu or cuda[:N], got {text!r}")


def build_parser() -> argparse.ArgumentParser:
    from benchmark.profiles import PROFILES
    parser = argparse.ArgumentParser(prog="python -m benchmark", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="push scenes through lenses, attack the sensor images, write a table")
    run.add_argument("--lens", action="append", required=True, metavar="NAME|SPEC.toml",
                     help="lens to benchmark (repeatable): a registered name or a .toml spec path")
    run.add_argument("--attack", action="append", default=None, metavar="NAME|FILE.py:Class",
                     help="attacker to run (repeatable); default: every registered attacker")
    run.add_argument("--scenes", default="synthetic", help="synthetic (default), photos, or cityscapes:PATH")
    run.add_argument("--profile", default="quick", choices=list(PROFILES), help="run size (default: quick)")
    run.add_argument("--seeds", type=_seeds, default=[0], help="comma-separated seeds, e.g. 0,1,2 (default 0)")
    run.add_argument("--device", type=_device, default="cpu", help="cpu (default) or cuda[:N]")
    run.add_argument("--out", type=Path, default=None, help="output folder (default runs/<date-time>)")
    run.add_argument("--executor", default="local", metavar="local|ray|ray://HOST:PORT",
                     help="where tasks run: here (default), a local Ray instance, or a Ray cluster")
    run.add_argument("--publish", action="store_true",
                     help="also write one leaderboard entry per lens to leaderboard/entries/ and re-render it")
    run.add_argument("--plate-format", default=None, metavar="FORMAT",
                     help="plate strings the privacy bound counts: L = letter, D = digit (default: the scene generator's)")
    run.add_argument("--budget-s", type=_budget, default=None, metavar="SECONDS",
                     help="wall-time budget of each expensive step (an attacker's fit, restore or read; the bound): "
                          "a step past it gives a failed row with a clear message (default: none)")
    run.add_argument("--frames", type=int, default=30, metavar="T",
                     help="frames of a static plate for the video bound (default 30; T = 1 is always reported)")
    run.add_argument("--dry-run", action="store_true",
                     help="print the task plan (cached or to compute, measured cost per task) and compute nothing")
    train = sub.add_parser("train", help="train (or load) a co-designed lens; under torchrun, data-parallel over the ranks")
    train.add_argument("--lens", required=True, choices=_codesign_lenses(), help="co-design scheme registered as a lens")
    train.add_argument("--profile", default="quick", choices=list(PROFILES), help="run size (default: quick)")
    train.add_argument("--seed", type=int, default=0, help="training seed (default 0)")
    train.add_argument("--device", type=_device, default="cpu",
                       help="cpu (default; gloo under torchrun) or cuda (NCCL under torchrun, one GPU per rank)")
    sub.add_parser("list", help="list registered lenses, attackers and scene sets")
    rep = sub.add_parser("report", help="render leaderboard/README.md and charts from leaderboard/entries/")
    rep.add_argument("--dir", type=Path, default=None, help="leaderboard folder (default: the repository's)")
    study = sub.add_parser("study", help="measure a modelling-choice study into leaderboard/studies/ and re-render")
    study.add_argument("name", choices=["psf-grid", "utility-size"],
                       help="psf-grid: PSF support, pupil grid, oversampling vs error and time; "
                            "utility-size: SegFormer variants vs mIoU at one profile's budget")
    study.add_argument("--profile", default="quick", choices=list(PROFILES), help="utility-size's budget (default: quick)")
    study.add_argument("--dir", type=Path, default=None, help="leaderboard folder (default: the repository's)")
    return parser


def _codesign_lenses() -> list[str]:
    from lenses.codesign.schemes import SCHEMES
    return [name for name, scheme in SCHEMES.items() if scheme.optics]  # "fixed" is no registered lens


def cmd_train(args: argparse.Namespace) -> int:
    from benchmark.cache import cache_root
    from benchmark.profiles import get_profile
    from lenses.codesign.builtin import START_SPEC
    from lenses.codesign.distributed import session
    from lenses.codesign.schemes import SCHEMES
    from lenses.codesign.trainer import CoDesign
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


def cmd_list() -> int:
    import attacks
    import lenses
    from benchmark.scenes import SCENE_SETS
    print("lenses:")
    for name, target in lenses.available().items():
        print(f"  {name:22s} {target}")
    print("attackers:")
    for name, target in attacks.available().items():
        print(f"  {name:22s} {target}")
    print("scene sets:")
    for name, text in SCENE_SETS.items():
        print(f"  {name:22s} {text}")
    return 0


def cmd_run(args: argparse.Namespace) -> int:
    from benchmark import api
    from benchmark.profiles import get_profile

    options = dict(lenses=args.lens, attacks=args.attack, profile=args.profile, seeds=args.seeds,
                   scenes=args.scenes, device=args.device, executor=args.executor,
                   plate_format=args.plate_format, frames=args.frames, budget_s=args.budget_s)
    if args.dry_run:
        print(api.plan(**options).render())
        return 0
    out = args.out or Path("runs") / _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    results = api.run(**options, out=out, meta={"command": sys.argv})
    print((out / "table.md").read_text())
    if args.publish:
        publish_run(results.output, get_profile(args.profile), out)
    print(f"wrote {out}/results.json, table.md, table.csv and samples_*.png ({results.meta['wall_s']:.1f} s)")
    return report_failures(results.failed)


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


def publish_run(result, profile, out: Path) -> None:
    from benchmark import leaderboard, leaderboard_report
    from benchmark.schema import ok_rows
    # The leaderboard reads version-1 rows until it reads the schema (config_hash = settings hash).
    rows = [{**r.flat(), "config_hash": r.settings_hash} for r in ok_rows(result.rows)]
    lens_info = result.lens_info
    paths = leaderboard.publish(rows, profile.to_dict(), lens_info)
    samples = leaderboard.LEADERBOARD / "samples"
    samples.mkdir(parents=True, exist_ok=True)
    copy_run_pictures(out, list(lens_info), profile.name, samples)
    leaderboard_report.render()
    leaderboard_report.update_readme(leaderboard.LEADERBOARD.parent / "README.md")
    print(f"published {len(paths)} leaderboard entries; rendered {leaderboard.LEADERBOARD / 'README.md'}")


def copy_run_pictures(out: Path, lens_names: list[str], profile: str, samples: Path) -> list[Path]:
    """Copy a published run's pictures into the leaderboard: each lens's first sample grid, and the
    run's plate-accuracy-vs-width chart (named after the run's lenses: one chart per published run)."""
    copied = []
    for name in lens_names:
        first = sorted(out.glob(f"samples_{name}_seed*.png"))
        if first:
            copied.append(Path(shutil.copyfile(first[0], samples / f"{name}__{profile}.png")))
    chart = out / "plate_accuracy_vs_width.png"
    if chart.is_file():
        copied.append(Path(shutil.copyfile(chart, samples / f"plate_width__{profile}__{'+'.join(lens_names)}.png")))
    return copied


def cmd_report(args: argparse.Namespace) -> int:
    from benchmark import leaderboard, leaderboard_report
    directory = args.dir or leaderboard.LEADERBOARD
    if not (directory / "entries").is_dir():
        raise ValueError(f"no leaderboard entries in {directory / 'entries'}; publish some with "
                         "`python -m benchmark run --lens NAME --publish`")
    for path in leaderboard_report.render(directory):
        print(f"wrote {path}")
    if args.dir is None and leaderboard_report.update_readme(leaderboard.LEADERBOARD.parent / "README.md"):
        print("updated the results table of README.md")
    return 0


def cmd_study(args: argparse.Namespace) -> int:
    from benchmark import leaderboard, leaderboard_report
    from benchmark.profiles import get_profile
    from benchmark.sensing import to_tensor
    from benchmark.scenes.loading import load_scene
    from benchmark.studies import psf_grid, utility_size
    directory = args.dir or leaderboard.LEADERBOARD
    t0 = time.perf_counter()
    if args.name == "psf-grid":
        scene = to_tensor([load_scene("synthetic", "val", 0, (256, 512), 0)])
        path = psf_grid.run(directory / "studies" / "psf_grid.json", scene)
    else:
        path = utility_size.run(directory / "studies" / "utility_size.json", get_profile(args.profile))
    print(f"wrote {path} ({time.perf_counter() - t0:.0f} s)")
    for written in leaderboard_report.render(directory):
        print(f"wrote {written}")
    return 0


def main(argv: list[str] | None = None) -> int:
    from lenses.registry import DuplicateNameError
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    args = build_parser().parse_args(argv)
    try:
        return {"list": cmd_list, "run": cmd_run, "report": cmd_report, "train": cmd_train,
                "study": cmd_study}[args.command](*(
            () if args.command == "list" else (args,)))
    except (ValueError, LookupError, NotImplementedError, FileNotFoundError, DuplicateNameError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
