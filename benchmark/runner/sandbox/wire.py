"""The messages between the runner and an attacker's process, on two pipes.

Runner -> attacker: pickled ``(op, payload)`` tuples. The attacker's process trusts the runner that
started it, so pickle is safe in that direction and carries what the runner hands any attacker (its
fit context's lens view, tensors, hints).

Attacker -> runner: never pickle. A message is a JSON header and, when it carries tensors, a
``safetensors`` blob, each behind an 8-byte big-endian length, both bounded: whatever the attacker's
code writes into the pipe is parsed as data, so a malformed or oversized message is a ``WireError``
(the attacker's row fails), never code run in the runner.
"""

from __future__ import annotations

import json
import pickle
import struct
from typing import Any, BinaryIO

import torch
from safetensors import SafetensorError
from safetensors.torch import load as load_tensors
from safetensors.torch import save as save_tensors

MAX_HEADER_BYTES = 16 * 2**20
MAX_TENSOR_BYTES = 8 * 2**30  # a paper-profile batch of restored frames is about 0.2 GiB
_LENGTH = struct.Struct(">Q")


class WireError(RuntimeError):
    """A message from an attacker's process that is not one (truncated, oversized or malformed)."""


class ProcessEnded(WireError):
    """The attacker's process closed its pipe: it exited or was ended."""


def _read_exact(stream: BinaryIO, n: int) -> bytes:
    chunks: list[bytes] = []
    left = n
    while left:
        chunk = stream.read(left)
        if not chunk:
            if left == n and not chunks:
                raise ProcessEnded("the attacker's process closed its pipe")
            raise WireError(f"message truncated: {n - left} of {n} bytes")
        chunks.append(chunk)
        left -= len(chunk)
    return b"".join(chunks)


def _read_block(stream: BinaryIO, limit: int, what: str) -> bytes:
    (n,) = _LENGTH.unpack(_read_exact(stream, _LENGTH.size))
    if n > limit:
        raise WireError(f"{what} of {n} bytes is over the limit of {limit} bytes")
    return _read_exact(stream, n) if n else b""


def encode_safe(header: dict[str, Any], tensors: dict[str, torch.Tensor] | None = None) -> bytes:
    """One attacker -> runner message: `header` (JSON-ready, else TypeError or ValueError) and `tensors`
    (name -> tensor), framed."""
    head = json.dumps(header, allow_nan=True).encode()
    blob = save_tensors({k: v.detach().contiguous().cpu() for k, v in tensors.items()}) if tensors else b""
    return _LENGTH.pack(len(head)) + head + _LENGTH.pack(len(blob)) + blob


def write(stream: BinaryIO, message: bytes) -> None:
    """Write one framed message and flush it."""
    stream.write(message)
    stream.flush()


def receive_safe(stream: BinaryIO) -> tuple[dict[str, Any], dict[str, torch.Tensor]]:
    """Read one attacker -> runner message: its header (a JSON object) and its tensors.

    Raises:
        ProcessEnded: the pipe closed before a message began.
        WireError: a truncated, oversized or malformed message.
    """
    head = _read_block(stream, MAX_HEADER_BYTES, "a message header")
    blob = _read_block(stream, MAX_TENSOR_BYTES, "a message's tensors")
    try:
        header = json.loads(head)
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise WireError(f"a message header is not JSON ({exc})") from None
    if not isinstance(header, dict):
        raise WireError(f"a message header is a JSON {type(header).__name__}, not an object")
    try:
        tensors = load_tensors(blob) if blob else {}
    except (SafetensorError, ValueError, RuntimeError) as exc:
        raise WireError(f"a message's tensors are not a safetensors blob ({exc})") from None
    return header, tensors


def send_trusted(stream: BinaryIO, op: str, payload: Any = None) -> None:
    """Write one runner -> attacker message (pickled: the attacker's process trusts its runner)."""
    data = pickle.dumps((op, payload), protocol=pickle.HIGHEST_PROTOCOL)
    write(stream, _LENGTH.pack(len(data)) + data)


def receive_trusted(stream: BinaryIO) -> tuple[str, Any]:
    """Read one runner -> attacker message (in the attacker's process only)."""
    data = _read_block(stream, 2**63, "a request")
    op, payload = pickle.loads(data)  # noqa: S301 - from the runner that started this process
    return op, payload
