"""Publishing to the leaderboard: a run's rows become entries (merged with stored ones), its
pictures are copied, and the leaderboard is re-rendered (`python -m benchmark run ... --publish`).

The entry format and the reading of entries live in ``benchmark.results.entries``; rendering
(tables, charts, web page) in ``benchmark.publish.report``.

Publishing reads the stored entries, merges and writes them back, then re-renders: two publishes into
one leaderboard at once would each merge into what the other has not written yet and one run's rows
would be lost, so a publish holds the leaderboard folder's lock (``entries.locked``, a kernel file lock
that dies with its holder) from the first read to the last write.
"""

from __future__ import annotations

import dataclasses
import glob
import logging
import shutil
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from benchmark.publish import report as leaderboard_report
from benchmark.publish.findings import co_designed
from benchmark.results.observer.published import ABOVE_CEILING
from benchmark.results.entries import (LEADERBOARD, Entry, entry_name, file_safe, locked, make_entry, read_entry,
                                       write_entry)
from benchmark.results.schema import Results, Row, read_results

log = logging.getLogger(__name__)

def _seed_specs(entry: Entry) -> dict[int, Any]:
    """The lens spec each seed of `entry` was measured with (from its rows' settings; a one-seed entry
    without settings falls back on the entry's spec)."""
    specs: dict[int, Any] = {}
    for row in entry.rows:
        spec = entry.settings.get(row.settings_hash or "", {}).get("lens")
        if isinstance(spec, dict):  # a reference (`sharp`) names itself instead of a spec
            specs.setdefault(row.seed, spec)
    if not specs and len(entry.seeds) == 1:
        specs[entry.seeds[0]] = entry.lens_spec
    return specs


def _design(spec: Any) -> Any:
    """A co-designed lens's spec before training: everything but its trained coefficients and the
    description naming its seed (every seed of one scheme shares it)."""
    if not isinstance(spec, dict):
        return spec
    mask = {k: v for k, v in (spec.get("mask") or {}).items() if k != "zernike_um"}
    return {**{k: v for k, v in spec.items() if k != "description"}, "mask": mask}


def merge_entries(old: Entry, new: Entry) -> Entry:
    """``new`` plus the rows of ``old`` whose (attack chain, seed) ``new`` lacks, if both measured the
    same lens under the same profile, with nets trained by the same co-design trainer version (rows'
    note ``trainer_version``); else ``new`` alone. Kept rows keep their provenance.

    The same lens: the same spec, or for a co-designed lens the same design (its coefficients are
    trained per seed, so a run of seed 1 adds to a stored seed 0). A seed both measured with different
    specs (re-trained into other coefficients) is replaced whole. Only (chain, seed) pairs that
    ``new`` measured successfully replace stored ones: a failed attacker is recorded without erasing
    an earlier measurement of it. The entry's spec and coefficients are its lowest seed's."""
    same = (lambda a, b: _design(a) == _design(b)) if co_designed(new.lens) else (lambda a, b: a == b)
    settings = lambda values: {k: v for k, v in values.items() if k != "description"}  # noqa: E731 - prose, not a setting
    if settings(old.profile_values) != settings(new.profile_values) or not same(old.lens_spec, new.lens_spec):
        return new
    versions = old.trainer_versions(), new.trainer_versions()
    if all(versions) and versions[0] != versions[1]:  # nets trained by another trainer: not the same thing
        return new
    old_specs, new_specs = _seed_specs(old), _seed_specs(new)
    have = {(row.attack, row.seed) for row in new.rows if row.ok}
    kept = [row for row in old.rows if (row.attack, row.seed) not in have
            and (row.seed not in new_specs or old_specs.get(row.seed) == new_specs[row.seed])]
    if not kept:
        return new
    rows = new.rows + kept
    used = {r.settings_hash for r in kept}
    settings = {**{k: v for k, v in old.settings.items() if k in used}, **new.settings}
    seeds = sorted({r.seed for r in rows})
    spec = new_specs.get(seeds[0], old_specs.get(seeds[0], new.lens_spec))
    coefficients = (list(spec["mask"]["zernike_um"]) if isinstance(spec, dict) and "zernike_um" in spec.get("mask", {})
                    else new.coefficients_um)
    return dataclasses.replace(new, rows=rows, settings=settings, seeds=seeds, lens_spec=spec,
                               coefficients_um=coefficients)


def publish(rows: Sequence[Row], profile: dict[str, Any], lens_info: dict[str, dict],
            directory: Path = LEADERBOARD, settings: dict[str, Any] | None = None, replace: bool = False
            ) -> list[Path]:
    """Write one entry per lens of a run's rows (the `sharp` reference included).

    An existing entry of the same (lens, profile, scenes) is merged (``merge_entries``), so a run
    with fewer attackers (or more seeds for some of them) cannot erase a richer one; rows this run
    measured replace the stored ones; with `replace` the run's entry replaces the stored one whole (a
    re-publish: nothing of an older version stays). Holds the leaderboard's lock (see the module docstring).
    """
    paths = []
    with locked(directory):
        for lens in dict.fromkeys(r.lens for r in rows):
            info = lens_info.get(lens, {})
            entry = make_entry(lens, [r for r in rows if r.lens == lens], profile, info.get("coefficients_um"),
                               info.get("spec"), settings)
            path = directory / "entries" / entry_name(lens, entry.profile, entry.scenes)
            if path.exists() and not replace:
                entry = merge_entries(read_entry(path), entry)
            paths.append(write_entry(path, entry))
    return paths


def _run_pictures(out: Path, prefix: str, lens: str) -> list[Path]:
    """A run's pictures of `lens` (`{prefix}_{lens}_seed*.png`), first seed first. The runner writes
    a lens given as a spec path with its "/" as "_" (benchmark.runner.pictures); the glob is escaped
    because a lens name is the user's text."""
    return sorted(out.glob(glob.escape(f"{prefix}_{lens}_seed".replace("/", "_")) + "*.png"))


def copy_run_pictures(out: Path, lens_names: Iterable[str], profile: str, samples: Path) -> list[Path]:
    """Copy a published run's pictures into the leaderboard: each lens's first sample grid (and
    co-design curves, for a trained lens). Names are made file-safe (``file_safe``): a lens given as a
    spec path names its pictures after the path with "/" as "_", as its entry is named. The run's
    plate-accuracy-vs-width chart is not copied: `report` draws one per entry from the entry's own
    per-plate outcomes (benchmark.publish.board_files), whatever the number of runs that published it."""
    lens_names = list(lens_names)
    samples.mkdir(parents=True, exist_ok=True)
    copied = []
    for name in lens_names:
        first = _run_pictures(out, "samples", name)
        if first:
            copied.append(Path(shutil.copyfile(first[0], samples / f"{file_safe(name)}__{file_safe(profile)}.png")))
        # A co-designed lens's training curves (its first seed's), beside its samples.
        curves = _run_pictures(out, "curves", name)
        if curves:
            copied.append(Path(shutil.copyfile(curves[0],
                                               samples / f"{file_safe(name)}__{file_safe(profile)}__curves.png")))
    return copied


def publish_run(rows: Sequence[Row], profile: dict[str, Any], lens_info: dict[str, dict], out: Path,
                directory: Path = LEADERBOARD, settings: dict[str, Any] | None = None, replace: bool = False
                ) -> list[Path]:
    """Publish a run: its entries, its pictures, then re-render the leaderboard (and the project
    README's results table when `directory` is the repository's). Returns the written entries.

    The whole of it holds the leaderboard's lock, so that a concurrent publish neither loses rows nor
    renders over this one's pages with an older set of entries. A run with a row failed for reading above
    the ideal observer's ceiling (``observer.published.fail_above_ceiling``) is refused: its readers' other
    figures are as suspect as that one."""
    above = [r for r in rows if not r.ok and r.error is not None and r.error.message.startswith(ABOVE_CEILING)]
    if above:
        raise ValueError(f"refusing to publish: {len(above)} row(s) read above the ideal observer's ceiling, e.g. "
                         f"{above[0].lens}/{above[0].attack} seed {above[0].seed}: {above[0].error.message}")  # type: ignore[union-attr]
    with locked(directory):
        paths = publish(rows, profile, lens_info, directory, settings, replace)
        copy_run_pictures(out, lens_info, profile["name"], directory / "samples")
        leaderboard_report.render(directory)
        if directory == LEADERBOARD:
            leaderboard_report.update_readme(LEADERBOARD.parent / "README.md", directory)
    log.info("published %d leaderboard entries; rendered %s", len(paths), directory / "README.md")
    return paths


def lens_info_from_results(results: Results) -> dict[str, dict]:
    """Per lens of a results file: its spec and Zernike coefficients (um), from its `lens` rows'
    settings (what a run's lens task reports; `publish` stores them in the entry)."""
    info: dict[str, dict] = {}
    for row in results.rows:
        spec = results.settings.get(row.settings_hash or "", {}).get("lens")
        if row.kind == "lens" and row.lens not in info and isinstance(spec, dict):
            info[row.lens] = {"spec": spec, "coefficients_um": list(spec["mask"]["zernike_um"])}
    return info


def publish_results(run: Path, directory: Path = LEADERBOARD) -> list[Path]:
    """Publish a finished run from its folder (`run/results.json` and its pictures), as
    `run --publish` would have: for runs made elsewhere (a cluster, a GPU machine) or without --publish."""
    results = read_results(Path(run) / "results.json")
    profile = results.meta.get("profile")
    if not isinstance(profile, dict) or "name" not in profile:
        raise ValueError(f"{Path(run) / 'results.json'} has no profile in its meta; only a run's own "
                         "results.json can be published")
    return publish_run(results.rows, profile, lens_info_from_results(results), Path(run), directory,
                       results.settings)
