"""Stand-ins the runner holds for an attacker that runs in a process of its own (``process``).

``isolated(spec)`` starts the process, loads the attacker there and returns a ``Restorer`` or ``Reader``
of the same name, threat model, requirements and hints, whose every method is a request to that
process. The runner uses it like any attacker; what it hands over is what the attacker's threat model
grants (``views``), and what comes back is checked data (``wire``): a fit report, restored images, reads.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from collections.abc import Iterable
from typing import Any

from torch import Tensor

import attacks
from benchmark.runner.sandbox.process import AttackerProcess, AttackerProcessError
from benchmark.runner.sandbox.views import LensView, RemoteRef

ISOLATED = "isolated:"
"""The prefix of an attacker spec that runs in its own process (``AttackerRef.spec``)."""


class _Remote:
    """The methods of an isolated attacker: each one a request to its process."""

    name: str
    process: AttackerProcess

    def __init__(self, process: AttackerProcess):
        self.process = process

    def close(self) -> None:
        """End the attacker's process."""
        self.process.close()

    def describe(self) -> dict[str, Any]:
        described, _ = self.process.call("describe")
        if not isinstance(described, dict):
            raise TypeError(f"returned {type(described).__name__}; expected a dict")
        return {**described, "isolated": True}

    def skip_reason(self, ctx: attacks.FitContext) -> str | None:
        payload, callbacks = _context(ctx)
        reason, _ = self.process.call("skip_reason", payload, callbacks)
        if reason is not None and not isinstance(reason, str):
            raise AttackerProcessError(f"skip_reason came back as {type(reason).__name__}")
        return reason

    def fit(self, ctx: attacks.FitContext) -> attacks.FitReport:
        self.check_requirements(ctx)  # type: ignore[attr-defined]
        payload, callbacks = _context(ctx)
        report, _ = self.process.call("fit", payload, callbacks)
        return _fit_report(report)

    def restore(self, sensor: Tensor) -> Tensor:
        _, tensors = self.process.call("restore", sensor)
        if "restored" not in tensors:
            raise AttackerProcessError("restore came back without its images")
        return tensors["restored"].to(sensor.device)

    def read(self, images: Tensor, hints: attacks.ReadHints | None = None) -> list[list[attacks.PlateRead]]:
        payload, callbacks = _hints(hints)
        answer, _ = self.process.call("read", (images, payload), callbacks)
        return _plate_reads(self._stages(answer))

    def read_batches(self, batches: Iterable[tuple[Tensor, attacks.ReadHints | None]]
                     ) -> list[list[list[attacks.PlateRead]]]:
        payload, callbacks = [], {}
        for i, (images, hints) in enumerate(batches):
            sent, more = _hints(hints, f"segment#{i}")  # each batch calls back its own segmenter
            payload.append((images, sent))
            callbacks.update(more)
        answer, _ = self.process.call("read_batches", payload, callbacks)
        per_batch = self._stages(answer)
        if not isinstance(per_batch, list):
            raise AttackerProcessError("read_batches came back without one answer per batch")
        return [_plate_reads(r) for r in per_batch]

    def _stages(self, answer: Any) -> Any:
        if not isinstance(answer, dict) or not isinstance(answer.get("stage_seconds"), dict):
            raise AttackerProcessError("a read came back without its reads and stage seconds")
        self.stage_seconds = {str(k): float(v) for k, v in answer["stage_seconds"].items()  # type: ignore[attr-defined]
                              if isinstance(v, (int, float))}
        return answer.get("reads")


class IsolatedRestorer(_Remote, attacks.Restorer):
    """A restorer running in its own process (class attributes set per attacker by ``isolated``)."""

    name = "isolated-restorer"
    threat_model = attacks.ThreatModel.SENSOR_ACCESS


class IsolatedReader(_Remote, attacks.Reader):
    """A reader running in its own process (class attributes set per attacker by ``isolated``)."""

    name = "isolated-reader"
    threat_model = attacks.ThreatModel.SENSOR_ACCESS


def is_stand_in(attacker: object) -> bool:
    """Whether `attacker` is the runner's stand-in for an attacker in its own process."""
    return isinstance(attacker, _Remote)


def isolated(spec: str) -> attacks.Attack:
    """The attacker of `spec` (a registered name or 'file.py:Class') loaded in a process of its own.

    Raises:
        PluginError: the attacker failed to import or construct there (named like what it raised).
        AttackerProcessError: the process ended or answered with something else than its description.
    """
    process = AttackerProcess(spec)
    try:
        meta, _ = process.call("load", {"spec": spec, "sys_path": list(sys.path)})
        cls = _proxy_class(meta, spec)
    except BaseException:
        process.close()
        raise
    return cls(process)


def _proxy_class(meta: Any, spec: str) -> type[_Remote]:
    """A proxy class carrying the attacker's class attributes (checked by ``Attack.__init_subclass__``)."""
    if not isinstance(meta, dict) or meta.get("kind") not in ("restorer", "reader"):
        raise AttackerProcessError(f"{spec!r}: its process described it as {meta!r}")
    name = meta.get("name")
    if not isinstance(name, str) or not name:
        raise AttackerProcessError(f"{spec!r}: its process gave the name {name!r}")
    try:
        attrs: dict[str, Any] = {
            "name": name, "threat_model": attacks.ThreatModel(meta.get("threat_model")),
            "requires": frozenset(_strings(meta.get("requires"))), "learns": meta.get("learns") is True,
            "reference": meta.get("reference") is True, "run_by_default": meta.get("run_by_default") is not False}
        base: type[_Remote] = IsolatedRestorer
        if meta["kind"] == "reader":
            attrs["hints"], base = frozenset(_strings(meta.get("hints"))), IsolatedReader
        return type(f"Isolated[{name}]", (base,), {"__module__": __name__, **attrs})
    except (TypeError, ValueError) as exc:
        raise AttackerProcessError(f"{spec!r}: its process described it with {exc}") from None


def _strings(value: Any) -> list[str]:
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise TypeError(f"a list of names expected, got {value!r}")
    return value


def _context(ctx: attacks.FitContext) -> tuple[attacks.FitContext, dict[str, Any]]:
    """The fit context an isolated attacker is sent (the lens as a ``LensView``, callables as call backs)."""
    callbacks = {k: v for k, v in (("train_pairs", ctx.train_pairs), ("segmenter", ctx.segmenter)) if v is not None}
    refs: dict[str, Any] = {k: RemoteRef(k) for k in callbacks}  # stand in for the callables, by design
    sent = dataclasses.replace(ctx, lens=None if ctx.lens is None else LensView.of(ctx.lens), **refs)
    return sent, callbacks


def _hints(hints: attacks.ReadHints | None, target: str = "segment") -> tuple[attacks.ReadHints | None, dict[str, Any]]:
    """The hints an isolated reader is sent (its segmenter as a call back named `target`)."""
    if hints is None or hints.segment is None:
        return hints, {}
    ref: Any = RemoteRef(target)
    return dataclasses.replace(hints, segment=ref), {target: hints.segment}


def _fit_report(report: Any) -> attacks.FitReport:
    if not isinstance(report, dict):
        raise AttackerProcessError(f"fit came back as {type(report).__name__}, not a report")
    curve = report.get("curve")
    seconds = report.get("stage_seconds")
    rising = report.get("still_rising")
    if not isinstance(seconds, dict) or not all(isinstance(v, (int, float)) for v in seconds.values()) \
            or rising not in (None, True, False):
        raise AttackerProcessError(f"fit came back with a malformed report: {report!r:.300}")
    try:
        fitted = None if curve is None else attacks.FitCurve(
            steps=tuple(int(s) for s in curve["steps"]), scores=tuple(float(s) for s in curve["scores"]),
            metric=str(curve["metric"]), stopped=str(curve["stopped"]), kept_step=int(curve["kept_step"]))
    except (KeyError, TypeError, ValueError) as exc:
        raise AttackerProcessError(f"fit came back with a malformed curve ({exc})") from None
    return attacks.FitReport(curve=fitted, still_rising=rising, stage_seconds={str(k): float(v) for k, v in seconds.items()})


def _plate_reads(reads: Any) -> list[list[attacks.PlateRead]]:
    """Reads as they came back ([text, box, score] per read, a list per image) made ``PlateRead``s."""
    if not isinstance(reads, list) or not all(isinstance(per, list) for per in reads):
        raise AttackerProcessError("reads came back as something other than one list per image")
    out = []
    for per_image in reads:
        row = []
        for item in per_image:
            ok = (isinstance(item, list) and len(item) == 3 and isinstance(item[0], str) and isinstance(item[1], list)
                  and len(item[1]) == 4 and all(_finite(v) for v in item[1]) and _finite(item[2]))
            if not ok:
                raise AttackerProcessError(f"a read came back malformed: {item!r:.200}")
            row.append(attacks.PlateRead(item[0], tuple(float(v) for v in item[1]), float(item[2])))  # type: ignore[arg-type]
        out.append(row)
    return out


def _finite(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
