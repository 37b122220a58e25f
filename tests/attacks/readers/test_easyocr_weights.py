"""EasyOCR's weights are loaded with ``weights_only=True``: a pickle that would run code when
unpickled, put where the recognizer's weights belong, is refused and never runs."""

from __future__ import annotations

import pickle

import pytest
import torch

from attacks.readers.plates import easyocr_models


class _Payload:
    """Unpickling this writes ``marker``: the proof that the file's code ran."""

    def __init__(self, marker: str) -> None:
        self.marker = marker

    def __reduce__(self):
        return (open, (self.marker, "w"))


@pytest.fixture
def fresh_readers():
    easyocr_models.load_easyocr.cache_clear()
    yield
    easyocr_models.load_easyocr.cache_clear()  # the other tests load the real weights again


def test_a_malicious_recognizer_file_is_refused_before_it_runs(tmp_path, monkeypatch, fresh_readers):
    """EasyOCR checks the file's MD5, which a chosen-prefix collision defeats: the test lets the
    file pass that check, as such a file would, so that only weights_only stands in its way."""
    import easyocr.easyocr
    from easyocr.utils import calculate_md5

    real_md5 = calculate_md5(str(easyocr_models.model_dir() / easyocr_models.RECOGNIZER_FILE))
    monkeypatch.setattr(easyocr.easyocr, "calculate_md5", lambda path: real_md5)
    marker = tmp_path / "pwned"
    folder = tmp_path / "models"
    folder.mkdir()
    # A torch-saved state dict whose value is an object that runs code when unpickled.
    torch.save({"module.weight": _Payload(str(marker))}, folder / easyocr_models.RECOGNIZER_FILE,
               pickle_protocol=pickle.HIGHEST_PROTOCOL)
    monkeypatch.setattr(easyocr_models, "model_dir", lambda files=easyocr_models.MODEL_FILES: folder)
    with pytest.raises(pickle.UnpicklingError, match="[Ww]eights only"):
        easyocr_models.load_easyocr(False)
    assert not marker.exists(), "the pickled payload ran while EasyOCR loaded its weights"


def test_easyocr_modules_load_weights_only_and_the_shipped_weights_still_load(fresh_readers):
    from easyocr import detection, recognition

    reader = easyocr_models.load_easyocr(False)
    assert reader.recognizer is not None
    for module in (detection, recognition):
        assert isinstance(module.torch, easyocr_models._WeightsOnlyTorch)
        assert module.torch.nn is torch.nn  # everything but load is torch's own
