"""A lens given as a spec file: known by its spec's name, its tasks keyed by the spec's content."""

from __future__ import annotations

from pathlib import Path

import pytest

import benchmark
from lenses import load_spec

SPECS = Path(__file__).resolve().parents[3] / "lenses" / "specs"
CAMERA = 'name = "my-camera"\n[mask]\nzernike_um = [0, 0, 0, {defocus}, 0, 0]\n'


def _plan(*lens: str | Path):
    return benchmark.plan([str(p) for p in lens], ["identity"], profile="smoke")


def _lens_keys(plan) -> list[str]:
    return [t.key for t in plan.tasks if t.lens]


def _camera(folder: Path, defocus: float = 0.5) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "cam.toml").write_text(CAMERA.format(defocus=defocus))
    return folder / "cam.toml"


def test_a_spec_file_lens_is_known_by_its_spec_name(tmp_path):
    plan = _plan("ideal", _camera(tmp_path))
    assert {t.lens for t in plan.tasks if t.lens} == {"ideal", "my-camera"}
    assert all("cam.toml" not in t.key and str(tmp_path) not in t.key for t in plan.tasks)


def test_an_edited_spec_is_a_new_task_and_a_moved_one_is_not(tmp_path):
    before = _lens_keys(_plan(_camera(tmp_path / "a")))
    edited = _lens_keys(_plan(_camera(tmp_path / "a", defocus=0.6)))
    moved = _lens_keys(_plan(_camera(tmp_path / "b")))
    assert len(before) == len(edited) and not set(before) & set(edited)
    assert moved == before


def test_the_registered_lens_s_own_spec_file_is_that_lens():
    assert _lens_keys(_plan(SPECS / "defocus.toml")) == _lens_keys(_plan("defocus"))


def test_a_spec_named_like_another_registered_lens_is_refused(tmp_path):
    spec = tmp_path / "fake.toml"
    spec.write_text(CAMERA.format(defocus=0.5).replace("my-camera", "defocus"))
    with pytest.raises(ValueError, match=r"named 'defocus', which is the registered lens 'defocus'.*another name"):
        _plan(spec)


def test_two_lenses_of_one_name_are_refused(tmp_path):
    with pytest.raises(ValueError, match=r"both named 'my-camera'.*own `name`"):
        _plan(_camera(tmp_path / "a"), _camera(tmp_path / "b", defocus=0.7))
    with pytest.raises(ValueError, match=r"both named 'defocus'"):
        _plan("defocus", SPECS / "defocus.toml")


def test_the_spec_file_s_example_lenses_plan_under_their_names():
    examples = sorted((SPECS / "examples").glob("*.toml"))
    plan = _plan(*examples)
    assert {t.lens for t in plan.tasks if t.lens} == {load_spec(p).name for p in examples}
