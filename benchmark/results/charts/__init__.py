"""Every chart of the suite, one module per chart; ``new_figure`` and ``save_figure`` are the one way
a chart is made and written.

Charts are built on matplotlib's object API (``matplotlib.figure.Figure``), never through pyplot:
no global backend to select before an import, no figure registry to leak, and ``savefig`` renders
with the Agg canvas whatever backend the caller's session (a notebook, a GUI) has chosen. Each
chart module offers a ``*_figure`` function that returns the figure (for tests and notebooks) and a
``write_*`` function that saves it. Inside ``encrypted_pictures`` (a sealed run's tasks), what
``save_figure`` writes is encrypted before it reaches the disk (``benchmark.store.cipher``).
"""

from __future__ import annotations

import contextlib
import contextvars
import io
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from matplotlib.figure import Figure

from benchmark.store.cache import atomic_write_bytes

# No matplotlib version stamp in the PNGs: the same data render to byte-identical files.
PNG_METADATA: dict[str, Any] = {"Software": None}


# (file name, PNG bytes) -> the bytes to write: a sealed run's encryption, None elsewhere.
_ENCRYPT: contextvars.ContextVar[Callable[[str, bytes], bytes] | None] = contextvars.ContextVar("encrypt", default=None)


@contextlib.contextmanager
def encrypted_pictures(encrypt: Callable[[str, bytes], bytes] | None) -> Iterator[None]:
    """Within it, ``save_figure`` writes ``encrypt(file name, bytes)`` instead of the bytes (None: as they are)."""
    token = _ENCRYPT.set(encrypt)
    try:
        yield
    finally:
        _ENCRYPT.reset(token)


def new_figure(**kwargs: Any) -> Figure:
    """A figure detached from pyplot (``kwargs`` as for ``matplotlib.figure.Figure``: figsize in inches, ...)."""
    return Figure(**kwargs)


def save_figure(fig: Figure, path: Path | str, dpi: int = 100, metadata: dict | None = None,
                layout: bool | tuple[float, float, float, float] = True) -> Path:
    """Lay out (``layout``: True for tight_layout, a rect tuple for tight_layout(rect=...), False for
    none), write ``fig`` to ``path`` (parent folders created; format from the suffix) with fixed
    metadata (``metadata`` added to PNG_METADATA). Returns the path."""
    if layout is True:
        fig.tight_layout()
    elif layout:
        fig.tight_layout(rect=layout)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    # Rendered in memory and written atomically: a full disk or a kill mid-write leaves the old chart
    # or none, never a truncated one that would be published.
    buffer = io.BytesIO()
    fig.savefig(buffer, format=path.suffix.lstrip(".") or "png", dpi=dpi,
                metadata={**PNG_METADATA, **(metadata or {})})
    encrypt = _ENCRYPT.get()
    atomic_write_bytes(path, buffer.getvalue() if encrypt is None else encrypt(path.name, buffer.getvalue()))
    return path
