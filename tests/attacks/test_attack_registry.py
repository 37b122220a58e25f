"""Plugin loading: file specs, other distributions' entry points, broken plugins, duplicates."""

from __future__ import annotations

import logging
import sys
import textwrap

import pytest

import attacks
from attacks.registry import DuplicatePluginError, UnknownPluginError, discover, similar

GROUP = "privacy_lens_bench.attacks"

PLUGIN_SOURCE = textwrap.dedent(
    """
    import attacks

    class {cls}(attacks.Restorer):
        name = "{name}"
        threat_model = attacks.ThreatModel.SENSOR_ACCESS

        def __init__(self, strength=1.0):
            self.strength = strength

        def restore(self, sensor):
            return (sensor * self.strength).clamp(0, 1)
    """
)


@pytest.fixture
def site(tmp_path, monkeypatch):
    """A fresh sys.path entry; ``add(dist, entries, modules)`` installs a fake distribution."""
    root = tmp_path / "site"
    root.mkdir()
    monkeypatch.syspath_prepend(str(root))  # also invalidates importlib's finder caches
    before = set(sys.modules)

    def add(dist: str, entries: dict[str, str], modules: dict[str, str]) -> None:
        info = root / f"{dist}-1.0.dist-info"
        info.mkdir()
        (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: 1.0\n")
        lines = "".join(f"{name} = {target}\n" for name, target in entries.items())
        (info / "entry_points.txt").write_text(f"[{GROUP}]\n{lines}")
        for module, source in modules.items():
            (root / f"{module}.py").write_text(source)

    yield add
    for module in set(sys.modules) - before:
        del sys.modules[module]


def test_load_from_file_path_with_options(tmp_path):
    path = tmp_path / "my_attack.py"
    path.write_text(PLUGIN_SOURCE.format(cls="MyAttack", name="my-attack"))
    attack = attacks.load(f"{path}:MyAttack", strength=0.5)
    assert isinstance(attack, attacks.Restorer) and attack.name == "my-attack"
    assert attack.strength == 0.5
    assert type(attacks.load(f"{path}:MyAttack")) is type(attack)  # imported once


def test_file_path_errors_are_clear(tmp_path):
    path = tmp_path / "my_attack.py"
    path.write_text("class NotAnAttack:\n    pass\n")
    with pytest.raises(UnknownPluginError, match="does not exist"):
        attacks.load(f"{tmp_path / 'missing.py'}:X")
    with pytest.raises(LookupError, match=r"defines no 'Nope'.*NotAnAttack"):
        attacks.load(f"{path}:Nope")
    with pytest.raises(TypeError, match="not a subclass of attacks.Attack"):
        attacks.load(f"{path}:NotAnAttack")


def test_entry_point_of_another_distribution(site):
    site(
        "other_dist",
        {"their-attack": "their_attack_mod:TheirAttack"},
        {"their_attack_mod": PLUGIN_SOURCE.format(cls="TheirAttack", name="their-attack")},
    )
    registered = attacks.available()
    assert registered["their-attack"] == "their_attack_mod:TheirAttack"
    assert "their_attack_mod" not in sys.modules  # listing imports nothing
    assert {"identity", "wiener-known-psf"} <= set(registered)  # our built-ins, same path
    assert attacks.load("their-attack", strength=2.0).strength == 2.0


def test_broken_plugin_is_skipped_and_reported(site, caplog):
    site(
        "broken_dist",
        {"broken": "broken_mod:Broken", "bad-syntax": "bad_syntax_mod:Bad"},
        {"broken_mod": "raise ImportError('needs libfoo')\n", "bad_syntax_mod": "def (:\n"},
    )
    with caplog.at_level(logging.WARNING, logger="attacks.registry"):
        loaded, failures = attacks.load_all()
    assert {f.name for f in failures} == {"broken", "bad-syntax"}
    assert "needs libfoo" in next(f.error for f in failures if f.name == "broken")
    assert "SyntaxError" in next(f.error for f in failures if f.name == "bad-syntax")
    assert "'broken'" in caplog.text
    assert {"identity", "wiener-known-psf"} <= {a.name for a in loaded}
    only, failed = attacks.load_all(["identity", "broken"])
    assert [a.name for a in only] == ["identity"] and [f.name for f in failed] == ["broken"]


def test_requested_unknown_name_raises_with_suggestions():
    with pytest.raises(attacks.UnknownAttackError, match=r"'wiener'.*Did you mean 'wiener-known-psf'"):
        attacks.load_all(["identity", "wiener"])
    with pytest.raises(LookupError, match=r"Registered .*'identity'"):
        attacks.load("identiy")
    assert similar("identiy", ["identity", "gray-world"]) == ["identity"]


def test_duplicate_names_across_distributions_are_an_error(site):
    source = PLUGIN_SOURCE.format(cls="Twin", name="twin")
    site("dist_a", {"twin": "twin_a:Twin"}, {"twin_a": source})
    site("dist_b", {"twin": "twin_b:Twin"}, {"twin_b": source})
    with pytest.raises(DuplicatePluginError, match=r"'twin'.*registered twice") as error:
        discover(GROUP)
    assert "dist_a 1.0 (twin_a:Twin)" in str(error.value)
    assert "dist_b 1.0 (twin_b:Twin)" in str(error.value)
    with pytest.raises(DuplicatePluginError):
        attacks.load("identity")


def test_registered_name_must_match_class_name(site):
    site("liar_dist", {"alias": "liar_mod:Liar"}, {"liar_mod": PLUGIN_SOURCE.format(cls="Liar", name="real-name")})
    with pytest.raises(TypeError, match=r"registered as 'alias'.*'real-name'"):
        attacks.load("alias")


def test_builtins_are_registered_by_entry_point():
    registered = attacks.available()
    for name, target in {
        "identity": "attacks.restorers.identity:Identity",
        "wiener-known-psf": "attacks.restorers.wiener_known_psf:WienerKnownPSF",
        "gray-world": "attacks.restorers.gray_world:GrayWorld",
    }.items():
        assert registered.get(name) == target, f"pyproject.toml must register {name} = {target!r}"


def test_a_file_plugin_named_like_a_registered_attacker_is_an_error_naming_both(tmp_path):
    path = tmp_path / "dup.py"
    path.write_text(PLUGIN_SOURCE.format(cls="Dup", name="identity"))
    with pytest.raises(DuplicatePluginError, match=r"'identity' is defined twice") as info:
        attacks.load_all([f"{path}:Dup"])
    assert f"file {path}:Dup" in str(info.value) and "attacks.restorers.identity:Identity" in str(info.value)
    first, second = tmp_path / "a.py", tmp_path / "b.py"
    first.write_text(PLUGIN_SOURCE.format(cls="A", name="mine"))
    second.write_text(PLUGIN_SOURCE.format(cls="B", name="mine"))
    with pytest.raises(DuplicatePluginError, match=r"a\.py:A and by file .*b\.py:B"):
        attacks.load_all([f"{first}:A", f"{second}:B"])


@pytest.mark.parametrize("attribute, source", [
    ("`name`", "import attacks\nclass X(attacks.Restorer):\n    threat_model = attacks.ThreatModel.SENSOR_ACCESS\n"
               "    def restore(self, s):\n        return s\n"),
    ("`threat_model`", "import attacks\nclass X(attacks.Restorer):\n    name = 'x'\n"
                       "    def restore(self, s):\n        return s\n"),
])
def test_a_class_missing_a_required_attribute_names_it(tmp_path, attribute, source):
    path = tmp_path / "x.py"
    path.write_text(source)
    loaded, failures = attacks.load_all([f"{path}:X"])
    assert not loaded and attribute in failures[0].error and failures[0].kind == "restorer"


def test_file_specs_and_other_distributions_entry_points_are_outside_the_suite_ours_are_not():
    from importlib.metadata import EntryPoint

    from attacks.registry import ATTACKS_GROUP, discover, outside_suite
    registered = discover(ATTACKS_GROUP)
    assert not any(outside_suite(name, registered) for name in registered)  # every built-in is ours
    foreign = {**registered, "foreign": EntryPoint("foreign", "their_pkg.attack:Foreign", ATTACKS_GROUP)}
    assert outside_suite("foreign", foreign)  # no distribution of ours behind it
    assert outside_suite("plugins/mine.py:Mine", registered) and not outside_suite("no-such-name", registered)


def test_load_all_hands_what_is_outside_the_suite_to_the_given_loader_and_imports_it_not(tmp_path):
    plugin = tmp_path / "never_imported.py"
    plugin.write_text("raise RuntimeError('imported into the runner')\n")
    asked = []

    class StandIn(attacks.Restorer):
        name = "stand-in"
        threat_model = attacks.ThreatModel.SENSOR_ACCESS

        def restore(self, sensor):
            return sensor

    def load_outside(spec):
        asked.append(spec)
        return StandIn()

    loaded, failures = attacks.load_all(["identity", f"{plugin}:X"], load_outside=load_outside)
    assert asked == [f"{plugin}:X"] and not failures
    assert [a.name for a in loaded] == ["identity", "stand-in"]
