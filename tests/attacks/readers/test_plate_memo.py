"""The plate stages' memory (attacks/readers/plates/memo.py): keyed by content, scoped, bounded, switchable."""

from __future__ import annotations

import numpy as np
import torch

from attacks.readers.plates import memo


class Owner:
    """Something a table can belong to (weakly referenced, like a segmenter or a recognizer)."""


def test_content_key_follows_bytes_shape_and_dtype_not_layout():
    a = np.arange(24, dtype=np.uint8).reshape(2, 4, 3)
    assert memo.content_key(a) == memo.content_key(a.copy()) == memo.content_key(torch.from_numpy(a))
    assert memo.content_key(a[:, ::2]) == memo.content_key(np.ascontiguousarray(a[:, ::2]))  # a strided view
    b = a.copy()
    b[1, 3, 2] += 1
    assert memo.content_key(b) != memo.content_key(a)
    assert memo.content_key(a.reshape(4, 2, 3)) != memo.content_key(a)
    assert memo.content_key(a.astype(np.int8)) != memo.content_key(a)


def test_tables_are_per_owner_scoped_by_fresh_and_off_when_forgetting():
    owner, other = Owner(), Owner()
    with memo.fresh():
        memo.ocr_memo(owner)["k"] = ("AB", 0.5)
        assert memo.ocr_memo(owner) == {"k": ("AB", 0.5)} and memo.ocr_memo(other) == {}
        assert memo.vehicles_memo(owner) == {}  # the stages' tables are apart
        with memo.fresh():
            assert memo.ocr_memo(owner) == {}
        assert memo.ocr_memo(owner) == {"k": ("AB", 0.5)}
        with memo.forgetting():
            assert memo.ocr_memo(owner) is None and memo.vehicles_memo(owner) is None
        assert memo.ocr_memo(owner) == {"k": ("AB", 0.5)}
    assert memo.ocr_memo(1) is None  # an int cannot be weakly referenced: nothing remembered


def test_a_full_table_is_emptied_and_a_dead_owner_takes_its_table(monkeypatch):
    monkeypatch.setattr(memo, "MAX_ENTRIES", 3)
    owner = Owner()
    with memo.fresh():
        table = memo.ocr_memo(owner)
        table.update({str(i): ("", 0.0) for i in range(3)})
        assert memo.ocr_memo(owner) == {}
        del owner, table
        assert len(memo._TABLES["ocr"]) == 0
