"""What an attacker's process writes back is parsed as data: framed JSON and safetensors, bounded, and
anything else is a WireError, never code run in the runner."""

from __future__ import annotations

import io
import json
import pickle
import struct

import pytest
import torch

from benchmark.runner.sandbox.wire import (ProcessEnded, WireError, encode_safe, receive_safe, receive_trusted,
                                           send_trusted)


def _frame(head: bytes, blob: bytes = b"") -> io.BytesIO:
    return io.BytesIO(struct.pack(">Q", len(head)) + head + struct.pack(">Q", len(blob)) + blob)


def test_a_message_round_trips_its_header_and_tensors_bit_for_bit():
    t = torch.rand(2, 3, 5, 7)
    header, tensors = receive_safe(io.BytesIO(encode_safe({"type": "result", "value": [1, "a", None]}, {"x": t})))
    assert header == {"type": "result", "value": [1, "a", None]}
    assert torch.equal(tensors["x"], t) and tensors["x"].dtype == t.dtype


def test_a_runner_request_round_trips():
    stream = io.BytesIO()
    send_trusted(stream, "restore", torch.ones(1, 3, 2, 2))
    stream.seek(0)
    op, payload = receive_trusted(stream)
    assert op == "restore" and torch.equal(payload, torch.ones(1, 3, 2, 2))


@pytest.mark.parametrize("stream, named", [
    (_frame(b"not json"), "not JSON"),
    (_frame(b"[1, 2]"), "JSON list, not an object"),
    (_frame(json.dumps({"type": "result"}).encode(), b"garbage, not tensors"), "not a safetensors blob"),
    (io.BytesIO(struct.pack(">Q", 2**40)), "over the limit"),
    (io.BytesIO(struct.pack(">Q", 10) + b"{}"), "truncated"),
])
def test_a_malformed_answer_is_a_wire_error_naming_what_is_wrong(stream, named):
    with pytest.raises(WireError, match=named):
        receive_safe(stream)


def test_a_pickle_written_back_is_refused_not_unpickled():
    class Boom:
        def __reduce__(self):
            return (exec, ("raise SystemExit('unpickled')",))
    evil = pickle.dumps(Boom())
    with pytest.raises(WireError):
        receive_safe(io.BytesIO(struct.pack(">Q", len(evil)) + evil + struct.pack(">Q", 0)))


def test_a_closed_pipe_is_told_apart_from_a_truncated_message():
    with pytest.raises(ProcessEnded):
        receive_safe(io.BytesIO(b""))
    with pytest.raises(WireError) as caught:
        receive_safe(io.BytesIO(b"\x00\x00"))
    assert not isinstance(caught.value, ProcessEnded)
