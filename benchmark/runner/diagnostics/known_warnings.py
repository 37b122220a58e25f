"""The library warnings every run printed, each known to be harmless here, silenced by message and module.

`silence_known_warnings()` is called by the CLI and by `benchmark.run`; it adds one filter per
warning below, matched on the start of the message and on the module that raises it, so that any
other warning (including a new one from the same libraries) still shows.
"""

from __future__ import annotations

import warnings

# (category, message regex, module regex, why it is harmless)
KNOWN_WARNINGS: tuple[tuple[type[Warning], str, str, str], ...] = (
    # EasyOCR quantizes its CPU recognizer with torch.ao.quantization.quantize_dynamic when it builds
    # the Reader; torch announces that API's removal in 2.10 (torch is pinned at 2.14.1 by the machine's
    # wheels, where it still works and is what EasyOCR's published accuracy was measured with).
    (DeprecationWarning, r"torch\.ao\.quantization is deprecated", r"(easyocr|torch\.ao\.quantization)\.",
     "EasyOCR's dynamic quantization uses an API torch plans to remove; it works in the pinned torch"),
    # The quantized BiLSTM of that recognizer creates qint8 tensors, which torch also deprecates.
    (UserWarning, r"torch\.quantize_per_tensor, torch\.quantize_per_channel and other quantized tensor",
     r"torch\.ao\.nn\.quantized\.", "the quantized recognizer's qint8 tensors, same deprecation"),
    # EasyOCR's recognizer DataLoader asks for pinned memory; on a CPU-only machine torch ignores it.
    (UserWarning, r"'pin_memory' argument is set as true but no accelerator is found", r"torch\.utils\.data\.",
     "pinned memory requested by EasyOCR's DataLoader is meaningless without a GPU"),
)


def silence_known_warnings() -> None:
    """Ignore exactly the warnings of `KNOWN_WARNINGS` (idempotent: `warnings` drops duplicate filters)."""
    for category, message, module, _why in KNOWN_WARNINGS:
        warnings.filterwarnings("ignore", message=message, category=category, module=module)
