"""The runner's handle on one attacker's process (``worker``): start it, ask it, answer its call backs, end it.

The process is a fresh interpreter (not a fork: a fork would hold a copy of the runner's memory, scenes
and plate texts included), in a session of its own so that ending it ends whatever it started. Its pids
are known to the runner's leftover-process check (``live_pids``), which must not end it between calls.
"""

from __future__ import annotations

import contextlib
import itertools
import os
import re
import signal
import subprocess
import sys
import weakref
from collections.abc import Callable, Iterator, Mapping
from typing import Any

import torch

from benchmark.runner.sandbox.wire import ProcessEnded, WireError, receive_safe, send_trusted

_LIVE: set[int] = set()


def live_pids() -> set[int]:
    """The pids of the attacker processes this process holds open."""
    return set(_LIVE)


class AttackerProcessError(RuntimeError):
    """The attacker's process ended, broke its protocol, or was ended after an earlier failure."""


class PluginError(RuntimeError):
    """What the attacker's code raised in its process; its class takes the name of the original (``remote_error``)."""


def remote_error(name: Any, message: Any) -> PluginError:
    """A ``PluginError`` named like the exception the attacker raised (so rows read as they do in-process)."""
    name = name if isinstance(name, str) and re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]{0,79}", name) else "PluginError"
    message = message if isinstance(message, str) else repr(message)
    return type(name, (PluginError,), {"__module__": __name__})(message)


def _end(proc: subprocess.Popen, streams: tuple[Any, ...]) -> None:
    for stream in streams:
        with contextlib.suppress(OSError, ValueError):
            stream.close()
    if proc.poll() is None:
        with contextlib.suppress(OSError):
            os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            with contextlib.suppress(OSError):
                os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    else:  # its own children may outlive it
        with contextlib.suppress(OSError):
            os.killpg(proc.pid, signal.SIGKILL)
    _LIVE.discard(proc.pid)


class AttackerProcess:
    """One attacker (registered name or file spec) served in a process of its own."""

    def __init__(self, spec: str):
        self.spec = spec
        request_r, request_w = os.pipe()
        answer_r, answer_w = os.pipe()
        try:
            self.proc = subprocess.Popen(
                [sys.executable, "-m", "benchmark.runner.sandbox.worker", str(request_r), str(answer_w),
                 str(torch.get_num_threads())],
                pass_fds=(request_r, answer_w), stdin=subprocess.DEVNULL, start_new_session=True)
        finally:
            os.close(request_r)
            os.close(answer_w)
        self.requests, self.answers = os.fdopen(request_w, "wb"), os.fdopen(answer_r, "rb")
        _LIVE.add(self.proc.pid)
        self._ended = weakref.finalize(self, _end, self.proc, (self.requests, self.answers))
        self._pairs: dict[int, Iterator[Any]] = {}
        self._handles = itertools.count()
        self.broken: str | None = None

    def close(self) -> None:
        """End the process (and whatever it started)."""
        self._ended()

    def call(self, op: str, payload: Any = None, callbacks: Mapping[str, Callable[..., Any]] | None = None
             ) -> tuple[Any, dict[str, torch.Tensor]]:
        """Send one request and return its answer (value, tensors), answering the call backs it makes on the way.

        Raises:
            PluginError: the attacker's code raised (the process serves on).
            AttackerProcessError: the process ended, broke the protocol, or an earlier call left it ended.
        """
        if self.broken is not None:
            raise AttackerProcessError(f"the attacker process of {self.spec!r} was ended after {self.broken}")
        try:
            send_trusted(self.requests, op, payload)
            while True:
                header, tensors = receive_safe(self.answers)
                kind = header.get("type")
                if kind == "result":
                    return header.get("value"), tensors
                if kind == "error":
                    raise remote_error(header.get("error"), header.get("message"))
                if kind != "call":
                    raise WireError(f"an answer of unknown type {kind!r}")
                send_trusted(self.requests, "reply", self._answer(header, tensors, callbacks or {}))
        except PluginError:
            raise
        except BaseException as exc:  # a budget's timeout too: the process is mid-call, so it goes
            self.broken = f"{op} failed ({type(exc).__name__})"
            self.close()
            if isinstance(exc, (ProcessEnded, BrokenPipeError)):
                raise AttackerProcessError(f"the attacker process of {self.spec!r} exited during {op} "
                                           f"(exit code {self.proc.returncode})") from None
            if isinstance(exc, WireError):
                raise AttackerProcessError(f"the attacker process of {self.spec!r} answered {op} with "
                                           f"something that is not a message: {exc}") from None
            raise

    def _answer(self, header: dict[str, Any], tensors: dict[str, torch.Tensor],
                callbacks: Mapping[str, Callable[..., Any]]) -> tuple[str, Any]:
        """The runner's answer to a call back: ("ok", value) or ("error", why)."""
        target = header.get("target")
        try:
            if target == "train_pairs.open":
                handle = next(self._handles)
                self._pairs[handle] = iter(_callback(callbacks, "train_pairs")())
                return "ok", handle
            if target == "train_pairs.next":
                pairs = self._pairs.get(header.get("handle"))  # type: ignore[arg-type]
                if pairs is None:
                    return "error", f"no open pass over the training pairs with handle {header.get('handle')!r}"
                batch = next(pairs, None)
                if batch is None:
                    del self._pairs[header["handle"]]
                return "ok", batch
            images = tensors.get("images")
            if images is None or images.ndim != 4 or not images.is_floating_point():
                return "error", f"{target} takes images (B, 3, H, W) as floats"
            with torch.no_grad():
                return "ok", _callback(callbacks, str(target))(images)
        except Exception as exc:  # noqa: BLE001 - the attacker asked for something the runner cannot do
            return "error", f"{type(exc).__name__}: {exc}"


def _callback(callbacks: Mapping[str, Callable[..., Any]], target: str) -> Callable[..., Any]:
    fn = callbacks.get(target)
    if fn is None:
        raise LookupError(f"nothing named {target!r} was handed to this call (known: {sorted(callbacks)})")
    return fn

