"""A file plugin's task results are keyed by its text as well as its name: editing the plugin computes its
tasks again instead of serving the results of its old text; the same text keeps its key."""

from benchmark.runner.config import RunConfig
from benchmark.runner.planning import run_directory
from benchmark.runner.runner import file_key, select_attackers
from benchmark.runner.sandbox import ISOLATED
from benchmark.store.profiles import get_profile

PLUGIN = '''
from attacks import Restorer, ThreatModel


class Scale(Restorer):
    name = "scale"; threat_model = ThreatModel.SENSOR_ACCESS

    def restore(self, sensor):
        return (sensor * {factor}).clamp(0, 1)
'''


def _directory(tmp_path, spec):
    chosen = select_attackers([spec], isolate=False)
    cfg = RunConfig(lenses=["ideal"], attacks=[spec], scenes="synthetic", profile=get_profile("smoke"), seeds=[0],
                    cache_dir=tmp_path / "cache")
    return chosen.restorers[0], run_directory(cfg, chosen.restorers, chosen.readers)


def test_editing_a_file_plugin_changes_its_key_and_the_run_folder(tmp_path):
    path = tmp_path / "scale.py"
    path.write_text(PLUGIN.format(factor=1.0))
    ref, before = _directory(tmp_path, f"{path}:Scale")
    assert ref.settings_key.startswith("file-") and ref.identity == f"scale@{ref.settings_key}"
    assert _directory(tmp_path, f"{path}:Scale")[1] == before  # the same text: its cached tasks are found
    path.write_text(PLUGIN.format(factor=0.5))
    assert _directory(tmp_path, f"{path}:Scale")[1] != before


def test_registered_names_keep_their_key_and_an_isolated_file_spec_is_hashed_like_the_file():
    assert file_key("wiener-known-psf") == ""
    assert file_key(f"{ISOLATED}{__file__}:X") == file_key(f"{__file__}:X") != ""
