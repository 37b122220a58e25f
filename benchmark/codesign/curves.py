"""Training you can watch: per-step curves as JSON lines, TensorBoard events and a chart.

While a run trains, every step's numbers go to `<run>.live/curves.jsonl` (one JSON object per
step: L_seg, L_deb, the penalty, each gradient norm, the lambda applied, each coefficient, the
PSF radius) and to TensorBoard event files in `<run>.live/tensorboard/` (read them with
`tensorboard --logdir`, or `tensorboard.backend.event_processing`; no server is started). The
published run folder gets `curves.jsonl` (rewritten from the checkpointed curves, so a resumed
run has each step exactly once), the event files and `curves.png`; `curves.jsonl` and `curves.png`
carry the cache's checksum sidecar, the event files need none (every TFRecord carries its own
CRC32C, which TensorBoard checks).
"""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path
from typing import Any

from torch.utils.tensorboard import SummaryWriter

from benchmark.store.cache import seal, write_verified
from benchmark.results.charts import new_figure, save_figure
from benchmark.codesign.coefficients import noll_name

# TensorBoard groups: prefix of a stat's name -> folder of its tag.
_GROUPS = (("grad_", "grad_norm/"), ("lambda_", "lambda/"), ("adversary_", "adversary/"))
_LOSSES = {"seg": "loss/L_seg", "deb": "loss/L_deb", "penalty": "loss/penalty"}
PUBLISHED_FILES = ("curves.jsonl", "curves.png")  # the checksummed files `publish_into` writes


def tag(key: str) -> str:
    """TensorBoard tag of a per-step stat (grad_seg_norm -> grad_norm/seg, seg -> loss/L_seg, ...)."""
    if key in _LOSSES:
        return _LOSSES[key]
    for prefix, group in _GROUPS:
        if key.startswith(prefix):
            return group + key[len(prefix):].removesuffix("_norm")
    return key


class CurveLog:
    """Writes each step's entry as it comes; `history` (entries already run, after a resume) first."""

    def __init__(self, live_dir: Path, history: list[dict[str, Any]], enabled: bool = True):
        self.live_dir, self.enabled = Path(live_dir), enabled
        if not enabled:
            return
        self.live_dir.mkdir(parents=True, exist_ok=True)
        self._lines = open(self.live_dir / "curves.jsonl", "w", encoding="utf-8")
        for entry in history:
            self._lines.write(json.dumps(entry) + "\n")
        self._lines.flush()
        # purge_step drops the events an interrupted run wrote after its last checkpoint.
        self._events = SummaryWriter(str(self.live_dir / "tensorboard"), purge_step=len(history) or None)

    def write(self, entry: dict[str, Any]) -> None:
        if not self.enabled:
            return
        self._lines.write(json.dumps(entry) + "\n")
        self._lines.flush()
        step = int(entry["step"])
        for key, value in entry.items():
            if key == "step":
                continue
            if key == "coefficients_um":
                for j, c in enumerate(value):
                    self._events.add_scalar(f"coefficients_um/{noll_name(j + 1)}", c, step)
            else:
                self._events.add_scalar(tag(key), value, step)
        self._events.flush()

    def close(self) -> None:
        if self.enabled:
            self._lines.close()
            self._events.close()

    def publish_into(self, folder: Path, curves: list[dict[str, Any]], title: str) -> None:
        """Write curves.jsonl, the event files and curves.png of a finished run into `folder`."""
        folder = Path(folder)
        write_verified(folder / "curves.jsonl", "".join(json.dumps(entry) + "\n" for entry in curves).encode())
        if self.enabled and (self.live_dir / "tensorboard").is_dir():
            shutil.copytree(self.live_dir / "tensorboard", folder / "tensorboard")
        seal(chart(curves, folder / "curves.png", title))

    def remove_live(self) -> None:
        shutil.rmtree(self.live_dir, ignore_errors=True)


def _series(curves: list[dict[str, Any]], key: str) -> tuple[list[int], list[float]]:
    pairs = [(e["step"], e[key]) for e in curves if key in e and math.isfinite(e[key])]
    return [p[0] for p in pairs], [p[1] for p in pairs]


def chart(curves: list[dict[str, Any]], path: Path, title: str) -> Path:
    """Four panels over the steps: losses, optics-gradient norms (log), coefficients (um), PSF radius (px)."""
    fig = new_figure(figsize=(11, 7))
    axes = fig.subplots(2, 2, sharex=True)
    ax = axes[0, 0]
    for key in ("seg", "deb", "penalty"):
        ax.plot(*_series(curves, key), label=tag(key).split("/")[1])
    ax.set_yscale("log")
    ax.set_title("losses")
    ax.legend(fontsize=8)
    ax = axes[0, 1]
    for key in sorted({k for e in curves for k in e if k.startswith("grad_")}):
        ax.plot(*_series(curves, key), label="dL/dtheta " + tag(key).split("/")[1])
    lambdas = sorted({k for e in curves for k in e if k.startswith("lambda_")})
    for key in lambdas:
        steps, values = _series(curves, key)
        if len(set(values)) > 1:  # a fixed lambda is in the title, a varying one (MTAdam) is drawn
            ax.plot(steps, values, "--", label=f"applied {key}")
    ax.set_yscale("log")
    ax.set_title("optics-gradient norms (per um)")
    if ax.get_legend_handles_labels()[0]:  # a lens with fixed optics has none
        ax.legend(fontsize=8)
    ax = axes[1, 0]
    steps = [e["step"] for e in curves]
    for j in range(1, len(curves[0]["coefficients_um"]) if curves else 0):
        ax.plot(steps, [e["coefficients_um"][j] for e in curves], label=noll_name(j + 1))
    ax.set_title("mask coefficients (um of glass)")
    ax.set_xlabel("step")
    ax.legend(fontsize=8)
    ax = axes[1, 1]
    ax.plot(*_series(curves, "psf_radius_px"))
    ax.set_title("PSF RMS radius (px)")
    ax.set_xlabel("step")
    fig.suptitle(title, fontsize=9)
    return save_figure(fig, path)
