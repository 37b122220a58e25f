"""The torch/EasyOCR warnings every run used to print are silenced, each by message and module;
reading a plate with EasyOCR (a fresh process: the Reader, and its warnings, come once per process)
prints none of them, while the same read without the filters prints each (so the check can fail)."""

import os
import subprocess
import sys

import pytest

from benchmark.runner.diagnostics.known_warnings import KNOWN_WARNINGS

READ_ONE_PLATE = """
import sys, warnings
warnings.simplefilter("always")  # show every warning, also the DeprecationWarnings Python hides by default
if sys.argv[1] == "silenced":
    from benchmark.runner.diagnostics.known_warnings import silence_known_warnings
    silence_known_warnings()
import numpy as np
from attacks.readers.plates.easyocr_models import load_easyocr
from attacks.readers.plates.ocr import read_plates
crop = np.random.default_rng(0).integers(0, 255, (24, 100, 3), dtype=np.uint8)
print("read", read_plates(load_easyocr(), [crop])[0].raw is not None)
"""

# The start of each warning's text as torch prints it (the filters are regexes of the same).
TEXTS = ("torch.ao.quantization is deprecated", "torch.quantize_per_tensor, torch.quantize_per_channel",
         "'pin_memory' argument is set as true but no accelerator is found")


def read_one_plate(mode: str) -> str:
    env = {**os.environ, "OMP_NUM_THREADS": "1", "CUDA_VISIBLE_DEVICES": ""}
    proc = subprocess.run([sys.executable, "-c", READ_ONE_PLATE, mode], capture_output=True, text=True, env=env,
                          timeout=300)
    assert proc.returncode == 0 and "read True" in proc.stdout, proc.stderr[-3000:]
    return proc.stderr


@pytest.fixture(scope="module")
def stderr():
    return {mode: read_one_plate(mode) for mode in ("plain", "silenced")}


@pytest.mark.slow
@pytest.mark.parametrize("text", TEXTS)
def test_reading_a_plate_prints_none_of_the_known_warnings(stderr, text):
    assert text in stderr["plain"], "the warning no longer appears: drop its filter from KNOWN_WARNINGS"
    assert text not in stderr["silenced"]


def test_each_filter_is_scoped_to_a_message_and_a_module_and_says_why():
    assert len(KNOWN_WARNINGS) == len(TEXTS)
    for category, message, module, why in KNOWN_WARNINGS:
        assert issubclass(category, Warning) and message and module and why


def test_other_warnings_of_the_same_modules_still_show():
    import warnings

    from benchmark.runner.diagnostics.known_warnings import silence_known_warnings
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        silence_known_warnings()
        warnings.warn_explicit("torch.ao.quantization is deprecated", DeprecationWarning, "detection.py", 1,
                               module="easyocr.detection")
        warnings.warn_explicit("something else", UserWarning, "dataloader.py", 1, module="torch.utils.data.dataloader")
        warnings.warn_explicit("torch.ao.quantization is deprecated", DeprecationWarning, "x.py", 1, module="mycode")
    assert [str(w.message) for w in seen] == ["something else", "torch.ao.quantization is deprecated"]
