"""Command line: `python -m benchmark run ...` and `python -m benchmark list`."""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import logging
import os
import sys
import time
from pathlib import Path

# Nothing downloads at run time: guard the libraries that might try.
for _var in ("HF_HUB_OFFLINE", "TRANSFORMERS_OFFLINE", "HF_DATASETS_OFFLINE"):
    os.environ.setdefault(_var, "1")


def _seeds(text: str) -> list[int]:
    try:
        seeds = [int(s) for s in text.split(",") if s.strip() != ""]
    except ValueError:
        raise argparse.ArgumentTypeError(f"--seeds must be comma-separated integers like 0,1,2, got {text!r}") from None
    if not seeds:
        raise argparse.ArgumentTypeError("--seeds needs at least one integer")
    return seeds


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
    run.add_argument("--publish", action="store_true",
                     help="also write one leaderboard entry per lens to leaderboard/entries/ and re-render it")
    run.add_argument("--plate-format", default=None, metavar="FORMAT",
                     help="plate strings the privacy bound counts: L = letter, D = digit (default: the scene generator's)")
    run.add_argument("--frames", type=int, default=30, metavar="T",
                     help="frames of a static plate for the video bound (default 30; T = 1 is always reported)")
    sub.add_parser("list", help="list registered lenses, attackers and scene sets")
    rep = sub.add_parser("report", help="render leaderboard/README.md and charts from leaderboard/entries/")
    rep.add_argument("--dir", type=Path, default=None, help="leaderboard folder (default: the repository's)")
    return parser


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
    import lenses
    from benchmark import report, runner
    from benchmark.profiles import get_profile
    from benchmark.scenes import load_scenes

    profile = get_profile(args.profile)
    known = lenses.available()
    for name in args.lens:  # fail before any work on a typo
        if not (name.endswith(".toml") or Path(name).is_file() or name in known):
            lenses.load(name)
    load_scenes(args.scenes, "val", 0, profile.image_size, 0)  # validates the scene set name
    out = args.out or Path("runs") / _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    out.mkdir(parents=True, exist_ok=True)
    print(f"profile {profile.name}: {json.dumps(profile.to_dict())}")
    from benchmark.scenes import PLATE_FORMAT, plate_entropy_bits
    plate_format = args.plate_format or PLATE_FORMAT
    plate_entropy_bits(plate_format)  # validates the format before any work
    if args.frames < 1:
        raise ValueError(f"--frames must be >= 1, got {args.frames}")
    cfg = runner.RunConfig(lenses=args.lens, attacks=args.attack, scenes=args.scenes, profile=profile,
                           seeds=args.seeds, device=args.device, plate_format=plate_format, frames=args.frames)

    lens_info: dict[str, dict] = {}

    def pictures(outcome: runner.LensOutcome, seed: int) -> None:
        scores = {r["attack"]: f"PSNR {r['psnr_db']:.2f} dB, SSIM {r['ssim']:.3f}"
                  for r in outcome.rows if "psnr_db" in r}
        name = outcome.rows[0]["lens"]
        report.write_sample_grid(out / f"samples_{name}_seed{seed}.png", name,
                                 outcome.lens.psf().detach().cpu().numpy(), outcome.scene, outcome.sensor,
                                 outcome.restored, scores)
        spec = outcome.lens.current_spec()
        lens_info.setdefault(name, {"coefficients_um": list(spec.mask.zernike_um), "spec": spec.to_dict(),
                                    "samples": out / f"samples_{name}_seed{seed}.png"})

    t0 = time.perf_counter()
    rows, plates = runner.run(cfg, on_lens=pictures)
    meta = {"command": sys.argv, "profile": profile.to_dict(), "wall_s": time.perf_counter() - t0}
    report.write_results(out, rows, meta)
    if plates:
        report.write_plate_records(out, plates)
    table = report.write_tables(out, rows)
    print((out / "table.md").read_text())
    if args.publish:
        publish_run(rows, profile, lens_info)
    print(f"wrote {out}/results.json, table.md, table.csv and samples_*.png ({len(table)} table rows, "
          f"{meta['wall_s']:.1f} s)")
    return 0


def publish_run(rows: list[dict], profile, lens_info: dict[str, dict]) -> None:
    import shutil

    from benchmark import leaderboard, leaderboard_report
    paths = leaderboard.publish(rows, profile.to_dict(), lens_info)
    samples = leaderboard.LEADERBOARD / "samples"
    samples.mkdir(parents=True, exist_ok=True)
    for name, info in lens_info.items():
        shutil.copyfile(info["samples"], samples / f"{name}__{profile.name}.png")
    leaderboard_report.render()
    print(f"published {len(paths)} leaderboard entries; rendered {leaderboard.LEADERBOARD / 'README.md'}")


def cmd_report(args: argparse.Namespace) -> int:
    from benchmark import leaderboard, leaderboard_report
    directory = args.dir or leaderboard.LEADERBOARD
    if not (directory / "entries").is_dir():
        raise ValueError(f"no leaderboard entries in {directory / 'entries'}; publish some with "
                         "`python -m benchmark run --lens NAME --publish`")
    for path in leaderboard_report.render(directory):
        print(f"wrote {path}")
    return 0


def main(argv: list[str] | None = None) -> int:
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    args = build_parser().parse_args(argv)
    try:
        return {"list": cmd_list, "run": cmd_run, "report": cmd_report}[args.command](*(
            () if args.command == "list" else (args,)))
    except (ValueError, LookupError, NotImplementedError, FileNotFoundError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
