"""What a leaderboard entry may hold: field types and metric ranges, checked where entries are read
and written (``benchmark.results.entries``).

An entry is a JSON file that anyone can edit or commit, and the tables and charts trust what it
says: a string where the seeds belong would render as its letters, a list where the entry belongs
would fail deep inside the renderer, and an mIoU of 7.5 inside matplotlib. Each check raises
ValueError naming the field (``rows[3].metrics.miou``), the value and what would be valid; the
readers add the file's path.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from typing import Any

from benchmark.results.ensemble import WIDTH_VALUE
from benchmark.results.plate_scoring import READABLE_MIN_WIDTH_PX
from benchmark.results.schema import Row

# The scene sets name their scenes <scenes>/<split>/<seed>/<index> (benchmark.scenes.loading).
SCENE_NAME = re.compile(r"^[^/]+/[^/]+/(\d+)/")
# How far a row's PSNR may sit from the mean of its per-scene values, which are stored rounded.
PSNR_TOLERANCE_DB = 1e-3

# Fields of a version-2 entry: name -> (is it required, what it holds).
FIELDS: dict[str, tuple[bool, str]] = {
    "entry_version": (True, "the format version"),
    "lens": (True, "a non-empty string"),
    "profile": (True, "a non-empty string"),
    "scenes": (True, "a non-empty string"),
    "seeds": (True, "a list of non-negative integers"),
    "profile_values": (True, "an object (the profile's settings)"),
    "coefficients_um": (False, "null or a list of finite numbers"),
    "lens_spec": (False, "null or an object (the lens spec)"),
    "settings": (False, "an object: settings hash -> settings"),
    "rows": (True, "a list of row objects"),
    "unit_ids": (False, "an object: key -> list of unit ids"),
}

_FRACTION = (0.0, 1.0, "a fraction")
_NON_NEGATIVE = (0.0, math.inf, "not negative")
# Metrics whose value has a fixed range: name -> (low, high, what it is). Names not listed here
# (PSNR, the bound's bits, ...) only have to be finite, which the row schema checks.
METRIC_RANGES: dict[str, tuple[float, float, str]] = {
    **dict.fromkeys(("miou", "mean_acc", "overall_acc", "plate_acc", "plate_det", "bound_limited"), _FRACTION),
    "ssim": (-1.0, 1.0, "an SSIM"),
    **dict.fromkeys(("plate_cer", "fit_s", "images_per_s", "psf_size_px"), _NON_NEGATIVE),
}
# Families of metrics named by a prefix or suffix (per-class IoUs, counts, per-image times).
_PREFIX_RANGES = (("iou_", _FRACTION), ("bound_ceiling_", _FRACTION), ("n_", _NON_NEGATIVE))
_SUFFIX_RANGES = (("_s_per_image", _NON_NEGATIVE),)


def metric_range(name: str) -> tuple[float, float, str] | None:
    """(low, high, what) for a metric with a fixed range, else None."""
    if name in METRIC_RANGES:
        return METRIC_RANGES[name]
    for prefix, found in _PREFIX_RANGES:
        if name.startswith(prefix):
            return found
    for suffix, found in _SUFFIX_RANGES:
        if name.endswith(suffix):
            return found
    return None


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_number(value: Any) -> bool:
    return (isinstance(value, (int, float)) and not isinstance(value, bool)) and math.isfinite(value)


def _valid(name: str, value: Any) -> bool:
    if name in ("lens", "profile", "scenes"):
        return isinstance(value, str) and bool(value)
    if name == "seeds":
        return isinstance(value, list) and all(_is_int(s) and s >= 0 for s in value)
    if name in ("profile_values", "settings"):
        return isinstance(value, dict)
    if name == "coefficients_um":
        return value is None or (isinstance(value, list) and all(_is_number(v) for v in value))
    if name == "lens_spec":
        return value is None or isinstance(value, dict)
    if name == "rows":
        return isinstance(value, list) and all(isinstance(r, dict) for r in value)
    if name == "unit_ids":
        return isinstance(value, dict) and all(isinstance(v, list) for v in value.values())
    return True


def _shown(value: Any) -> str:
    """A value as an error message shows it (long ones cut)."""
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def check_entry_json(d: Any) -> None:
    """Raise ValueError naming the field when `d` (a parsed version-2 entry) breaks ``FIELDS``."""
    if not isinstance(d, dict):
        raise ValueError(f"an entry is a JSON object with the fields {sorted(FIELDS)}, got a JSON "
                         f"{type(d).__name__}: {_shown(d)}")
    missing = [name for name, (required, _) in FIELDS.items() if required and name not in d]
    if missing:
        raise ValueError(f"the entry lacks field(s) {missing}")
    unknown = sorted(set(d) - set(FIELDS))
    if unknown:
        raise ValueError(f"the entry has unknown field(s) {unknown}; valid: {sorted(FIELDS)}")
    for name, (_, what) in FIELDS.items():
        if name in d and not _valid(name, d[name]):
            raise ValueError(f"field {name!r} must be {what}, got {_shown(d[name])}")


def check_rows(rows: Sequence[Row], lens: str, profile: str, scenes: str, seeds: Sequence[int]) -> None:
    """Raise ValueError naming the row and field when a row does not belong to its entry (another lens,
    profile, scene set or seed than the entry lists) or a metric is outside its range (``metric_range``)."""
    for i, row in enumerate(rows):
        where = f"rows[{i}] ({row.lens}/{row.attack} seed {row.seed})"
        for field, expected in (("lens", lens), ("profile", profile), ("scenes", scenes)):
            if getattr(row, field) != expected:
                raise ValueError(f"{where}: {field} {getattr(row, field)!r} is not the entry's {expected!r}")
        for field in ("attack", "restorer", "reader", "threat_model"):
            value = getattr(row, field)
            if value is not None and not isinstance(value, str):
                raise ValueError(f"{where}: {field} must be a string, got {_shown(value)}")
        if row.seed not in seeds:
            raise ValueError(f"{where}: seed {row.seed} is not one of the entry's seeds {list(seeds)}")
        for name, value in row.metrics.items():
            found = metric_range(name)
            if found is not None and not found[0] <= value <= found[1]:
                low, high, what = found
                raise ValueError(f"{where}: metrics.{name} = {value} is outside [{low}, {high}] ({name} is {what})")


def check_units(rows: Sequence[Row]) -> None:
    """Raise ValueError naming the row and field when the rows' per-unit outcomes contradict themselves or
    their metrics: a second row of one (kind, chain, seed); a unit of another seed than its row's; a
    per-plate ``correct`` other than 0 or 1; an ``n_plates``, ``plate_acc`` or ``psnr_db`` other than its
    own units give; and, within a seed, plate rows that score different plates or that record widths on some
    rows and not others. Each would change a published figure without a run having measured it (the
    ensemble aligns a seed's chains by plate id, so a renamed id would drop plates from it quietly)."""
    first_of: dict[tuple[str, str, int], int] = {}
    plate_rows: dict[int, list[int]] = {}
    for i, row in enumerate(rows):
        where = f"rows[{i}] ({row.lens}/{row.attack} seed {row.seed})"
        key = (row.kind, row.attack, row.seed)
        if key in first_of:
            raise ValueError(f"{where}: a second {row.kind} row of {row.attack!r} at seed {row.seed} (the first is "
                             f"rows[{first_of[key]}]); an entry holds one row per chain and seed")
        first_of[key] = i
        units = row.units
        if units is None:
            continue
        for name in units.names():
            named = SCENE_NAME.match(name)  # names of the suite's scene sets; others say no seed
            if named is not None and int(named.group(1)) != row.seed:
                raise ValueError(f"{where}: units id {name!r} is not of the row's seed {row.seed} (scene names are "
                                 "<scenes>/<split>/<seed>/<index>)")
        if units.unit == "plate":
            bad = sorted({v for v in units.values.get("correct", ()) if v not in (0, 1)}, key=repr)
            if bad:
                raise ValueError(f"{where}: units.values.correct holds {bad[:3]}; a plate's outcome is 0 or 1")
            if row.ok and "correct" in units.values:
                plate_rows.setdefault(row.seed, []).append(i)
        elif units.unit == "scene" and row.ok and "psnr_db" in units.values and "psnr_db" in row.metrics:
            values = units.values["psnr_db"]
            if row.metrics.get("n_images") == len(values) and abs(math.fsum(values) / len(values)
                                                                   - row.metrics["psnr_db"]) > PSNR_TOLERANCE_DB:
                raise ValueError(f"{where}: metrics.psnr_db = {row.metrics['psnr_db']} but its {len(values)} scenes' "
                                 f"units average {math.fsum(values) / len(values):.4f} dB")
    for seed, members in plate_rows.items():
        _check_seed_plates(seed, [(i, rows[i]) for i in members])
        for i in members:
            _check_plate_metrics(f"rows[{i}] ({rows[i].lens}/{rows[i].attack} seed {seed})", rows[i])


def _check_plate_metrics(where: str, row: Row) -> None:
    values = row.units.values  # type: ignore[union-attr]
    correct = values["correct"]
    widths = values.get(WIDTH_VALUE)
    counted = [c for c, w in zip(correct, widths) if w >= READABLE_MIN_WIDTH_PX] if widths else list(correct)
    # A metric the row does not state is recomputed from the units where it is shown; one it states must agree.
    n = row.metrics.get("n_plates")
    if n is not None and n != len(counted):
        raise ValueError(f"{where}: metrics.n_plates = {n} but its units hold {len(counted)} pooled plates")
    acc = row.metrics.get("plate_acc")
    if counted and acc is not None and abs(acc - sum(counted) / len(counted)) > 1e-9:
        raise ValueError(f"{where}: metrics.plate_acc = {acc} but its units read {sum(counted)} of {len(counted)} "
                         "pooled plates")


def _check_seed_plates(seed: int, members: Sequence[tuple[int, Row]]) -> None:
    (i0, r0), rest = members[0], members[1:]
    names0 = set(r0.units.names())  # type: ignore[union-attr]
    has_widths = WIDTH_VALUE in r0.units.values  # type: ignore[union-attr]
    for i, row in rest:
        units = row.units
        assert units is not None
        if (WIDTH_VALUE in units.values) != has_widths:
            with_, without = (i0, i) if has_widths else (i, i0)
            raise ValueError(f"seed {seed}: rows[{with_}] records plate widths and rows[{without}] does not; a "
                             "seed's plate rows record them all or none")
        names = set(units.names())
        if names != names0:
            raise ValueError(f"seed {seed}: rows[{i0}] ({r0.attack}) and rows[{i}] ({row.attack}) score different "
                             f"plates ({len(names0 - names)} ids only in the first, {len(names - names0)} only in the "
                             "second); every plate row of a seed scores the same plates")
