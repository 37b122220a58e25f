"""The process-wide switches that keep third-party libraries offline, set on import.

- ``ORT_DISABLE_TELEMETRY=1``: the official ONNX Runtime Linux wheels upload usage events to
  ``mobile.events.data.microsoft.com`` from their own threads (and keep a device id and an event store
  under ``~/.cache/Microsoft``); ``disable_telemetry_events()`` does not stop them, the variable does,
  when it is set before ONNX Runtime creates its environment.
- ``HF_HUB_OFFLINE=1``, ``TRANSFORMERS_OFFLINE=1``, ``HF_DATASETS_OFFLINE=1``: ``from_pretrained`` only
  ever takes a local path; nothing downloads weights at run time.

Each is set only when the environment names no value, so a user can still override it. ``attacks``
and the utility net's modules import this module before they import ONNX Runtime or transformers.
"""

import os

OFFLINE_VARIABLES = ("ORT_DISABLE_TELEMETRY", "HF_HUB_OFFLINE", "TRANSFORMERS_OFFLINE", "HF_DATASETS_OFFLINE")

for _var in OFFLINE_VARIABLES:
    os.environ.setdefault(_var, "1")
