"""One attacker in a process of its own: ``python -m benchmark.runner.sandbox.worker REQUEST_FD RESPONSE_FD``.

The runner (``sandbox.process``) starts it, sends requests (``load``, ``describe``, ``skip_reason``, ``fit``,
``restore``, ``read``, ``read_batches``, ``close``) on one pipe and reads the answers on the other
(``wire``). The attacker's code runs here only: it cannot reach the runner's scenes, their plate texts or
its scoring, whatever it imports or walks. What it may use comes in the requests: its fit context with a
``LensView`` in place of the lens, and ``RemoteRef`` callables (training pairs, segmenters) that call back
into the runner for their results. Whatever the attacker raises, a ``SystemExit`` included, is answered as
an error and the process keeps serving; what it prints goes to stderr, never into the pipe.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import os
import sys
from collections.abc import Iterator
from typing import Any, BinaryIO

import torch

from benchmark.runner.sandbox.views import RemoteRef
from benchmark.runner.sandbox.wire import ProcessEnded, encode_safe, receive_trusted, write


class Host:
    """Serves one attacker's requests until the runner closes the pipe or says ``close``."""

    def __init__(self, requests: BinaryIO, responses: BinaryIO):
        self.requests, self.responses = requests, responses
        self.attacker: Any = None

    def serve(self) -> None:
        while True:
            try:
                op, payload = receive_trusted(self.requests)
            except ProcessEnded:
                return
            if op == "close":
                return
            try:
                header, tensors = self.handle(op, payload)
                message = encode_safe({"type": "result", **header}, tensors)
            except BaseException as exc:  # noqa: BLE001 - a SystemExit of the plugin's is its error, not ours
                message = encode_safe({"type": "error", "error": type(exc).__name__, "message": str(exc)})
            write(self.responses, message)

    def handle(self, op: str, payload: Any) -> tuple[dict, dict[str, torch.Tensor] | None]:
        if op == "load":
            return {"value": self.load(payload["spec"], payload["sys_path"])}, None
        if self.attacker is None:
            raise RuntimeError(f"request {op!r} before the attacker was loaded")
        if op == "describe":
            return {"value": self.attacker.describe()}, None
        if op == "skip_reason":
            reason = self.attacker.skip_reason(self.local(payload))
            if reason is not None and not isinstance(reason, str):
                raise TypeError(f"skip_reason returned {type(reason).__name__}; expected a str or None")
            return {"value": reason}, None
        if op == "fit":
            return {"value": _report(self.attacker.fit(self.local(payload)))}, None
        if op == "restore":
            out = self.attacker.restore(payload)
            if not isinstance(out, torch.Tensor):
                raise TypeError(f"restore returned {type(out).__name__}; expected a torch.Tensor")
            return {"value": None}, {"restored": out}
        if op == "read":
            images, hints = payload
            reads = _reads(self.attacker.read(images, self.local(hints)))
            return {"value": {"reads": reads, "stage_seconds": self.stage_seconds()}}, None
        if op == "read_batches":
            batches = [(images, self.local(hints)) for images, hints in payload]
            reads = [_reads(r) for r in self.attacker.read_batches(batches)]
            return {"value": {"reads": reads, "stage_seconds": self.stage_seconds()}}, None
        raise ValueError(f"unknown request {op!r}")

    def load(self, spec: str, sys_path: list[str]) -> dict[str, Any]:
        import attacks
        sys.path[:0] = [p for p in sys_path if p not in sys.path]
        self.attacker = attacks.load(spec)
        kind = ("reader" if isinstance(self.attacker, attacks.Reader)
                else "restorer" if isinstance(self.attacker, attacks.Restorer) else None)
        if kind is None:
            raise TypeError(f"{spec!r} is neither an attacks.Restorer nor an attacks.Reader")
        cls = type(self.attacker)
        return {"name": self.attacker.name, "kind": kind, "threat_model": cls.threat_model.value,
                "requires": sorted(cls.requires), "hints": sorted(getattr(cls, "hints", ())),
                "learns": bool(cls.learns), "reference": bool(cls.reference), "run_by_default": bool(cls.run_by_default)}

    def stage_seconds(self) -> dict[str, float]:
        return {str(k): float(v) for k, v in dict(getattr(self.attacker, "stage_seconds", {}) or {}).items()}

    def local(self, obj: Any) -> Any:
        """`obj` (a fit context or read hints) with each ``RemoteRef`` field made a call back to the runner."""
        if obj is None or not dataclasses.is_dataclass(obj):
            return obj
        stubs = {f.name: self.stub(getattr(obj, f.name)) for f in dataclasses.fields(obj)
                 if isinstance(getattr(obj, f.name), RemoteRef)}
        return dataclasses.replace(obj, **stubs) if stubs else obj

    def stub(self, ref: RemoteRef) -> Any:
        if ref.target == "train_pairs":
            return self.remote_pairs
        return lambda images: self.call_back(ref.target, images)

    def remote_pairs(self) -> Iterator[tuple[torch.Tensor, torch.Tensor]]:
        """A fresh pass over the runner's training pairs, one batch per call back."""
        handle = self.call_back("train_pairs.open")
        while True:
            batch = self.call_back("train_pairs.next", handle=handle)
            if batch is None:
                return
            yield batch

    def call_back(self, target: str, images: torch.Tensor | None = None, handle: int | None = None) -> Any:
        """Ask the runner to compute `target` (on `images`) and wait for its answer."""
        if images is not None and not isinstance(images, torch.Tensor):
            raise TypeError(f"{target} takes a torch.Tensor of images, got {type(images).__name__}")
        write(self.responses, encode_safe({"type": "call", "target": target, "handle": handle},
                                          {"images": images} if images is not None else None))
        op, (status, value) = receive_trusted(self.requests)
        if op != "reply":
            raise RuntimeError(f"expected the runner's reply to {target}, got {op!r}")
        if status != "ok":
            raise RuntimeError(f"the runner could not compute {target}: {value}")
        return value


def _number(x: Any) -> float:
    value = float(x)
    if not math.isfinite(value):
        raise ValueError(f"not a finite number: {x!r}")
    return value


def _report(report: Any) -> dict[str, Any]:
    """An ``attacks.FitReport`` as JSON (its fit wrapper has already checked its type)."""
    curve = report.curve
    return {"curve": None if curve is None else {
                "steps": [int(s) for s in curve.steps], "scores": [float(s) for s in curve.scores],
                "metric": str(curve.metric), "stopped": str(curve.stopped), "kept_step": int(curve.kept_step)},
            "still_rising": None if report.still_rising is None else bool(report.still_rising),
            "stage_seconds": {str(k): float(v) for k, v in dict(report.stage_seconds).items()}}


def _reads(reads: Any) -> list[list[list[Any]]]:
    """A reader's answer (one list of ``PlateRead`` per image) as JSON lists [text, box, score]."""
    from attacks import PlateRead
    if not isinstance(reads, list) or not all(isinstance(per, list) for per in reads):
        raise TypeError(f"read returned {type(reads).__name__}; expected one list of attacks.PlateRead per image")
    out = []
    for per_image in reads:
        if not all(isinstance(r, PlateRead) for r in per_image):
            raise TypeError("read returned an item that is not an attacks.PlateRead")
        out.append([[r.text, [_number(v) for v in r.box_xyxy], _number(r.score)] for r in per_image])
    return out


def main(argv: list[str]) -> None:
    requests, responses = os.fdopen(int(argv[0]), "rb"), os.fdopen(int(argv[1]), "wb")
    sys.stdout = sys.stderr  # a plugin's print must not land in the answers' pipe
    torch.set_num_threads(int(argv[2]) if len(argv) > 2 else torch.get_num_threads())
    logging.basicConfig(level=logging.INFO, format="[attacker process] %(levelname)s %(name)s: %(message)s")
    Host(requests, responses).serve()


if __name__ == "__main__":
    main(sys.argv[1:])
