"""Charts of a run, rendered from its results; ``save_figure`` is the one way they are written."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def save_figure(fig: plt.Figure, path: Path | str, dpi: int = 100, metadata: dict | None = None,
                layout: bool | tuple[float, float, float, float] = True) -> Path:
    """Lay out (``layout``: True for tight_layout, a rect tuple for tight_layout(rect=...), False for
    none), write ``fig`` to ``path`` (parent folders created) and free it. Returns the path."""
    if layout is True:
        fig.tight_layout()
    elif layout:
        fig.tight_layout(rect=layout)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi, metadata=metadata)
    plt.close(fig)
    return path
