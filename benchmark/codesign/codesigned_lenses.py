"""Co-designed lenses, registered through the `privacy_lens_bench.lenses` entry-point group.

`lenses.load("gp", profile=..., seed=..., device=..., cache_dir=...)` trains the lens in-suite
(or takes it from the cache) and returns it with its utility network and adversary attached.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from lenses.builtin import SPEC_DIR
from benchmark.codesign.schemes import SCHEMES
from benchmark.codesign.trainer import CoDesign, TrainedLens
from lenses.lens import Lens
from lenses.spec import load_spec

START_SPEC = SPEC_DIR / "codesign.toml"


def attach(trained: TrainedLens) -> Lens:
    """The trained lens with its networks and record as attributes (utility_net, adversary, training_record)."""
    lens = trained.lens
    object.__setattr__(lens, "utility_net", trained.utility_net)
    object.__setattr__(lens, "adversary", trained.adversary)
    object.__setattr__(lens, "training_record", trained.record)
    return lens


def codesigned(scheme: str, profile: Any = None, seed: int = 0, device: str = "cpu",
               cache_dir: Path | None = None, progress: bool = True, scenes: str = "synthetic", **_: Any) -> Lens:
    """Train (or load from the cache) the lens of `scheme` for this profile, seed and training scenes."""
    from benchmark.store.cache import cache_root
    from benchmark.store.profiles import get_profile
    run = CoDesign(load_spec(START_SPEC), SCHEMES[scheme], profile or get_profile("quick"), seed, device,
                   Path(cache_dir) if cache_dir else cache_root(), scene_set=scenes)
    return attach(run.load_or_train(progress=progress))


def trained_run(scheme: str, profile: Any, seed: int = 0, cache_dir: Path | None = None,
                scenes: str = "synthetic") -> bool | None:
    """Whether the cache (or the package's shipped copy) holds the finished co-design of `scheme` for
    this profile, seed and scenes, without training anything; None when `scheme` is not co-designed."""
    from benchmark.store.cache import cache_root
    if scheme not in SCHEMES:
        return None
    run = CoDesign(load_spec(START_SPEC), SCHEMES[scheme], profile, seed, "cpu",
                   Path(cache_dir) if cache_dir else cache_root(), scene_set=scenes)
    return run.load() is not None


def os_lens(**kw: Any) -> Lens:
    return codesigned("os", **kw)


def os_d_1(**kw: Any) -> Lens:
    return codesigned("os-d-1", **kw)


def os_d_100(**kw: Any) -> Lens:
    return codesigned("os-d-100", **kw)


def os_d_1000(**kw: Any) -> Lens:
    return codesigned("os-d-1000", **kw)


def os_d_mtadam(**kw: Any) -> Lens:
    return codesigned("os-d-mtadam", **kw)


def gp(**kw: Any) -> Lens:
    return codesigned("gp", **kw)


def gp_literal(**kw: Any) -> Lens:
    return codesigned("gp-literal", **kw)


def os_info(**kw: Any) -> Lens:
    return codesigned("os-info", **kw)
