"""An attacker in a process of its own does what it does in the runner's (same restorations, same
reads, its fit handed the lens's PSF, gain and training pairs through call backs), reports its errors
by their names, and cannot break the runner: its exit, a malformed answer or a child it leaves behind
end with its process."""

from __future__ import annotations

import os
import textwrap
import time

import pytest
import torch

import attacks
from benchmark.runner.sandbox import AttackerProcessError, PluginError, is_stand_in, isolated, live_pids
from lenses import load as load_lens

pytestmark = pytest.mark.slow  # each test starts an attacker process (a fresh interpreter importing torch)

PLUGIN = textwrap.dedent('''
    import os, subprocess, sys
    import torch
    from attacks import FitReport, PlateRead, Reader, Restorer, ThreatModel


    class Gain(Restorer):
        name = "gain"; threat_model = ThreatModel.LENS_ACCESS; requires = frozenset({"lens", "train_pairs"})

        def fit(self, ctx):
            self.g = ctx.lens.gain()
            self.k = ctx.lens.psf().shape[-1]
            self.batches = sum(1 for _ in ctx.train_pairs())
            return FitReport(stage_seconds={"measure": 0.25})

        def restore(self, s):
            print("printed, not in the pipe")
            return (s / self.g.view(1, 3, 1, 1)).clamp(0, 1) * 0 + self.batches / 100 + self.k / 1000

        def describe(self):
            return {**super().describe(), "pid": os.getpid()}


    class Hostile(Reader):
        name = "hostile"; threat_model = ThreatModel.SENSOR_ACCESS; hints = frozenset({"segment"})

        def read(self, images, hints=None):
            labels = hints.segment(images)
            return [[PlateRead(f"L{int(labels[i].sum())}", (0.0, 0.0, 4.0, 2.0), 0.5)] for i in range(len(images))]

        def skip_reason(self, ctx):
            mode = os.environ.get("HOSTILE_MODE", "")
            if mode == "exit":
                raise SystemExit(3)
            if mode == "die":
                os._exit(7)
            if mode == "garbage":
                fd = int(sys.argv[2])
                os.write(fd, b"\\x00\\x00\\x00\\x00\\x00\\x00\\x00\\x05{bad}\\x00\\x00\\x00\\x00\\x00\\x00\\x00\\x00")
            if mode == "child":
                self.child = subprocess.Popen(["sleep", "600"])
                return str(self.child.pid)
            return None
''')


@pytest.fixture
def plugin(tmp_path):
    path = tmp_path / "plug.py"
    path.write_text(PLUGIN)
    return str(path)


def test_an_isolated_restorer_is_fitted_through_the_lens_view_and_call_backs_and_restores(plugin):
    lens = load_lens("defocus", profile="smoke")
    pairs = [(torch.rand(1, 3, 8, 8), torch.rand(1, 3, 8, 8))] * 3
    stand_in = isolated(f"{plugin}:Gain")
    try:
        assert is_stand_in(stand_in) and isinstance(stand_in, attacks.Restorer)
        assert (stand_in.name, stand_in.threat_model, stand_in.requires) == (
            "gain", attacks.ThreatModel.LENS_ACCESS, frozenset({"lens", "train_pairs"}))
        with pytest.raises(attacks.MissingRequirementError, match="train_pairs"):
            stand_in.fit(attacks.FitContext(lens=lens))
        report = stand_in.fit(attacks.FitContext(lens=lens, train_pairs=lambda: iter(pairs)))
        assert report == attacks.FitReport(stage_seconds={"measure": 0.25})
        out = stand_in.restore(torch.rand(2, 3, 4, 4))
        k = lens.psf().shape[-1]
        assert out.shape == (2, 3, 4, 4) and torch.allclose(out, torch.full_like(out, 3 / 100 + k / 1000))
        described = stand_in.describe()
        assert described["isolated"] is True and described["pid"] != os.getpid()
    finally:
        stand_in.close()
    assert stand_in.process.proc.pid not in live_pids()


def test_a_builtin_restores_the_same_isolated_as_in_the_runners_process():
    lens = load_lens("defocus", profile="smoke")
    sensor = lens(torch.rand(1, 3, 32, 48)).clamp(0, 1)
    here, there = attacks.load("wiener-known-psf"), isolated("wiener-known-psf")
    try:
        ctx = attacks.FitContext(lens=lens)
        here.fit(ctx)
        there.fit(ctx)
        assert torch.allclose(here.restore(sensor), there.restore(sensor), atol=1e-6)
    finally:
        there.close()


def test_a_reader_calls_back_for_its_segmenter_and_its_reads_come_back_checked(plugin):
    reader = isolated(f"{plugin}:Hostile")
    try:
        images = torch.rand(2, 3, 6, 6)
        segment = lambda x: torch.ones(x.shape[0], x.shape[2], x.shape[3], dtype=torch.long)  # noqa: E731
        reads = reader.read(images, attacks.ReadHints(segment=segment))
        assert reads == [[attacks.PlateRead("L36", (0.0, 0.0, 4.0, 2.0), 0.5)]] * 2
        twice = lambda x: 2 * segment(x)  # noqa: E731
        batches = reader.read_batches([(images[:1], attacks.ReadHints(segment=segment)),
                                       (images[1:], attacks.ReadHints(segment=twice))])
        assert batches == [[[attacks.PlateRead("L36", (0.0, 0.0, 4.0, 2.0), 0.5)]],
                           [[attacks.PlateRead("L72", (0.0, 0.0, 4.0, 2.0), 0.5)]]]  # each batch its own segmenter
        with pytest.raises(PluginError) as caught:
            reader.read(images, attacks.ReadHints())  # no segmenter handed over: as in the runner's process
        assert type(caught.value).__name__ == "TypeError" and "not callable" in str(caught.value)

        def broken(x):
            raise ValueError("no net for these")
        with pytest.raises(PluginError, match="the runner could not compute segment: ValueError: no net for these"):
            reader.read(images, attacks.ReadHints(segment=broken))
        assert reader.read(images[:1], attacks.ReadHints(segment=segment)) == [reads[0]]  # and serves on
    finally:
        reader.close()


def test_a_plugins_system_exit_is_its_error_and_its_process_serves_on(plugin, monkeypatch):
    monkeypatch.setenv("HOSTILE_MODE", "exit")
    reader = isolated(f"{plugin}:Hostile")
    try:
        with pytest.raises(PluginError) as caught:
            reader.skip_reason(attacks.FitContext())
        assert type(caught.value).__name__ == "SystemExit" and str(caught.value) == "3"
        assert reader.describe()["name"] == "hostile"
    finally:
        reader.close()


@pytest.mark.parametrize("mode, named", [("die", r"exited during skip_reason \(exit code 7\)"),
                                         ("garbage", "answered skip_reason with something that is not a message")])
def test_a_process_that_dies_or_writes_garbage_fails_the_call_and_stays_ended(plugin, monkeypatch, mode, named):
    monkeypatch.setenv("HOSTILE_MODE", mode)
    reader = isolated(f"{plugin}:Hostile")
    with pytest.raises(AttackerProcessError, match=named):
        reader.skip_reason(attacks.FitContext())
    with pytest.raises(AttackerProcessError, match="was ended after skip_reason failed"):
        reader.describe()
    assert reader.process.proc.poll() is not None and reader.process.proc.pid not in live_pids()


def test_a_child_the_plugin_left_ends_with_its_process(plugin, monkeypatch):
    monkeypatch.setenv("HOSTILE_MODE", "child")
    reader = isolated(f"{plugin}:Hostile")
    child = int(reader.skip_reason(attacks.FitContext()))
    os.kill(child, 0)  # alive while the attacker's process is
    reader.close()
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        try:
            os.kill(child, 0)
        except ProcessLookupError:
            break
        time.sleep(0.1)
    else:
        pytest.fail(f"the plugin's child {child} outlived its attacker process")


def test_a_plugin_that_fails_to_import_is_a_load_error_named_like_its_exception(tmp_path):
    bad = tmp_path / "bad.py"
    bad.write_text("raise ImportError('no such backend')\n")
    with pytest.raises(PluginError) as caught:
        isolated(f"{bad}:Nothing")
    assert type(caught.value).__name__ == "ImportError" and "no such backend" in str(caught.value)
    assert not live_pids()
