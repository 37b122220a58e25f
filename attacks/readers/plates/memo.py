"""What the plate attack's deterministic stages computed, remembered by the content of their input.

The runner reads plates with two readers (``lpdr``, ``lpdr-oracle``) on the sensor images and on
every restorer's output: a dozen chains over the same plate windows. Two stages are pure functions
of what they are given, so their results are remembered per process and reused whenever the same
input comes back, whichever chain or reader asks:

* vehicles (``lpdr``): the segmentation of an image, per segmenter and image content
  (``vehicles_memo``). An attacker finds vehicles on the image it attacks, with the network its
  threat model gives it: the lens's own network on sensor images, the clean one on restored
  images (``benchmark.runner.evaluation.run_reader``). So boxes are shared only between requests for the
  same network on byte-identical images: the chain whose restorer returns the sensor image
  unchanged (``raw``) and a reader run twice on one image. Boxes are never carried from one image to
  another (e.g. from the sensor image to a restorer's output, or from a frame to its windows): that
  would hand an attacker vehicles from an image or a network it does not attack with, and change
  what it reads.
* characters (OCR): english_g2's raw string and confidence for one plate crop, per recognizer and
  crop content (``ocr_memo``). Each crop's read is bit-identical whatever it is batched with
  (``attacks.readers.plates.ocr.SharedFeatures``), so the same pixels give the same read in any chain:
  ``raw>lpdr-oracle`` re-reads exactly the crops of ``lpdr-oracle``, and ``lpdr`` and
  ``lpdr-oracle`` often cut the same plate box from one image.

A remembered result is exactly the one the stage would compute again, so the reads, and every
score made of them, are unchanged; only the time is saved. Tables are held weakly by the
segmenter / recognizer they belong to and live as long as it does (the run's segmenters die with
their task; the recognizer lives as long as the process, so its table is emptied when it holds
``MAX_ENTRIES`` reads, about 30 MB). ``forgetting()`` turns the memory off and ``fresh()`` starts an
empty one (to measure the stages themselves, or what the memory saves).
"""

from __future__ import annotations

import contextlib
import hashlib
import weakref
from collections.abc import Iterator
from typing import Any

import numpy as np
from torch import Tensor

__all__ = ["MAX_ENTRIES", "content_key", "forgetting", "fresh", "ocr_memo", "vehicles_memo"]

Box = tuple[int, int, int, int]

MAX_ENTRIES = 100_000
"""A table holding this many results is emptied before it takes another (bounds a long run's memory)."""

# "vehicles": segmenter -> {image key: boxes}; "ocr": recognizer -> {crop key: (raw, score)}.
_TABLES: dict[str, weakref.WeakKeyDictionary[Any, dict]] = {"vehicles": weakref.WeakKeyDictionary(),
                                                            "ocr": weakref.WeakKeyDictionary()}
_ON = [True]


def content_key(image: Tensor | np.ndarray) -> str:
    """Identity of an array's content: BLAKE2b of its shape, dtype and bytes (32 hex digits)."""
    array = image.detach().cpu().contiguous().numpy() if isinstance(image, Tensor) else np.ascontiguousarray(image)
    digest = hashlib.blake2b(f"{array.shape}{array.dtype}".encode(), digest_size=16)
    digest.update(array.tobytes())
    return digest.hexdigest()


def _table(name: str, owner: Any) -> dict | None:
    if not _ON[0]:
        return None
    tables = _TABLES[name]
    try:
        table = tables.setdefault(owner, {})
    except TypeError:  # an owner that cannot be referenced weakly: nothing is remembered
        return None
    if len(table) >= MAX_ENTRIES:
        table.clear()
    return table


def vehicles_memo(segment: Any) -> dict[str, list[Box]] | None:
    """Image content key -> vehicle boxes found with ``segment``; None when not remembering."""
    return _table("vehicles", segment)


def ocr_memo(ocr: Any) -> dict[str, tuple[str, float]] | None:
    """Crop content key -> (raw string, confidence) read by ``ocr``; None when not remembering."""
    return _table("ocr", ocr)


@contextlib.contextmanager
def forgetting() -> Iterator[None]:
    """Within the block every stage computes afresh and nothing is remembered or looked up."""
    before = _ON[0]
    _ON[0] = False
    try:
        yield
    finally:
        _ON[0] = before


@contextlib.contextmanager
def fresh() -> Iterator[None]:
    """Within the block remember from an empty memory; what was remembered before is back after it."""
    saved = dict(_TABLES)
    _TABLES.update({name: weakref.WeakKeyDictionary() for name in saved})
    try:
        yield
    finally:
        _TABLES.update(saved)
