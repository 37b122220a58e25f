"""Seconds per co-design step of a profile on a device (the cost of the paper profile on a GPU).

One co-design run of the suite's trainer (``benchmark.codesign.trainer.CoDesign``, scheme ``gp`` by
default) is timed step by step: each step's batch, lens forward (PSF and sensor), utility net and
RED10 updates and optics update, as a co-design run computes them. What a step costs depends on the
profile's crop, batch, networks and lens, not on the weights, so the run starts from untrained
networks (no clean pre-training, no adversary pre-training: on the paper profile those alone are
hours on a CPU) and a few training scenes (``scenes``): the crops are cut from scenes of the
profile's size all the same, and no checkpoints are written (a run writes ten). The first ``warmup`` steps (allocation, cuDNN/oneDNN planning) are
timed but left out of the summary.

Run: ``python -m benchmark.studies.codesign_speed --profile paper --device cuda --out FILE.json``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any
from unittest import mock

import torch

from benchmark.codesign import trainer
from benchmark.codesign import adversary
from benchmark.codesign.codesigned_lenses import START_SPEC
from benchmark.codesign.schemes import SCHEMES
from benchmark.store.profiles import get_profile
from benchmark.store.provenance import provenance
from benchmark.codesign.utility.segformer import build_segformer
from lenses.spec import load_spec


def _synchronize(device: str) -> None:
    if device.startswith("cuda"):
        torch.cuda.synchronize(torch.device(device))


def time_codesign_steps(profile_name: str = "paper", device: str = "cpu", steps: int = 10, warmup: int = 3,
                        scheme: str = "gp", scenes: int = 4, seed: int = 0) -> dict[str, Any]:
    """Time ``warmup + steps`` co-design steps; returns the per-step seconds and their summary."""
    if steps < 1 or warmup < 0:
        raise ValueError(f"steps must be >= 1 and warmup >= 0, got steps={steps}, warmup={warmup}")
    base = get_profile(profile_name)
    profile = dataclasses.replace(base, n_train=scenes, codesign_steps=warmup + steps)
    cuda = device.startswith("cuda")
    if cuda:
        torch.cuda.reset_peak_memory_stats(torch.device(device))
    marks: list[float] = []

    def untrained_utility(p: Any, seed: int, dev: str, *args: Any, **kwargs: Any) -> torch.nn.Module:
        return build_segformer(p.utility_model).to(dev)  # type: ignore[arg-type]

    def untrained_adversary(lens: Any, sampler: Any, p: Any, seed: int, dev: str, *args: Any,
                            **kwargs: Any) -> tuple[torch.nn.Module, dict]:
        return adversary.for_training(adversary.build_adversary(p.adversary_width, lens), dev), {"steps": 0, "untrained": True}

    def on_step(step: int, stats: dict) -> None:
        _synchronize(device)  # the step's losses are read back already; this keeps the mark honest
        marks.append(time.perf_counter())

    with tempfile.TemporaryDirectory() as cache, \
            mock.patch.object(trainer, "clean_utility_net", untrained_utility), \
            mock.patch.object(trainer, "pretrain_adversary", untrained_adversary):
        run = trainer.CoDesign(load_spec(START_SPEC), SCHEMES[scheme], profile, seed, device, Path(cache))
        state = run._setup(progress=False)
        # A run checkpoints every tenth of its steps (every 3720 on paper); a short timed run would
        # checkpoint at every step, which is not what a step costs.
        run._save_checkpoint = lambda state: None  # type: ignore[method-assign]
        _synchronize(device)
        marks.append(time.perf_counter())
        run._loop(state, progress=False, stop_after=None, on_step=on_step)
        start_um, final_um = run.initial_um, state.lens.coefficients_um.detach().cpu()
    seconds = [b - a for a, b in zip(marks, marks[1:])]
    timed = seconds[warmup:]
    median = statistics.median(timed)
    return {
        "what": "co-design step seconds", "profile": profile_name, "scheme": scheme, "device": device,
        "train_crop": list(base.train_crop), "batch_size": base.batch_size, "image_size": list(base.image_size),
        "utility_model": base.utility_model, "adversary_width": base.adversary_width,
        "warmup_steps": warmup, "timed_steps": steps, "step_seconds": seconds,
        "median_s_per_step": median, "min_s_per_step": min(timed), "max_s_per_step": max(timed),
        "crops_per_s": base.batch_size / median,
        **({"torch_cuda_peak_mib": torch.cuda.max_memory_allocated(torch.device(device)) / 2**20} if cuda else {}),
        "initial_coefficients_um": [float(c) for c in start_um], "final_coefficients_um": [float(c) for c in final_um],
        "provenance": provenance(device),  # with the torch threads
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--profile", default="paper", help="profile whose step is timed (default: paper)")
    parser.add_argument("--device", default="cpu", help="cpu (default) or cuda[:N]")
    parser.add_argument("--steps", type=int, default=10, help="timed steps (default 10)")
    parser.add_argument("--warmup", type=int, default=3, help="steps left out of the summary (default 3)")
    parser.add_argument("--scheme", default="gp", choices=[n for n, s in SCHEMES.items() if s.optics])
    parser.add_argument("--out", type=Path, default=None, help="JSON file to write (default: print only)")
    args = parser.parse_args(argv)
    result = time_codesign_steps(args.profile, args.device, args.steps, args.warmup, args.scheme)
    text = json.dumps(result, indent=2)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text + "\n")
    print(f"{args.profile} co-design ({args.scheme}) on {result['provenance']['device']}: "
          f"{result['median_s_per_step']:.3f} s/step median of {args.steps} "
          f"({result['min_s_per_step']:.3f}-{result['max_s_per_step']:.3f}), {result['crops_per_s']:.1f} crops/s"
          + (f", peak {result['torch_cuda_peak_mib']:.0f} MiB" if "torch_cuda_peak_mib" in result else ""))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
