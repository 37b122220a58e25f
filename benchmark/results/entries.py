"""Leaderboard entries: one JSON file per (lens, profile, scenes) holding its typed rows.

Entries are written by `python -m benchmark run ... --publish` and never edited by hand; the
table (`leaderboard/README.md`), the web page and the charts are rendered from the entries alone by
`python -m benchmark report`, so they regenerate identically.

Entry format, version 2 (``ENTRY_VERSION``)::

    {"entry_version": 2, "lens", "profile", "scenes", "seeds",
     "profile_values": the profile's settings, "coefficients_um": the mask's Zernike coefficients,
     "lens_spec": the lens spec, "settings": {settings hash: lens + attacker settings},
     "rows": [benchmark.results.schema.Row as JSON, one per attack chain x seed],
     "unit_ids": {key: [unit ids]}}

A row's per-unit outcomes (``schema.Units``) name their units; in an entry the list of ids, which
every chain of one seed shares, is stored once under ``unit_ids`` and the row's ``units.ids`` holds
its key (a hash of the ids). Entries written before units existed have no ``unit_ids`` and rows
without units; they read as before (``Entry.units`` is None for them).

Version 1 stored per attack chain the metrics' mean, std and per-seed values, and one provenance
for the entry (or per merged row); ``migrate_entry`` turns it into version 2 without loss (the
per-seed values become the rows' metrics, ``wall_s`` their provenance, as ``schema.migrate_legacy_row``
does for results). Readers go through ``Entry``: its ``chains()`` summarise the rows of each attack
chain over the seeds (mean, seed std, per-seed values, 95 % interval where the rows carry one).
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import hashlib
import json
import math
import threading
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from benchmark.store.cache import atomic_write_text, exclusive
from benchmark.results.entry_checks import check_entry_json, check_rows, check_units
from benchmark.results.schema import LEGACY_PROVENANCE, Row, Units, dumps_compact, infer_legacy_kind

LEADERBOARD = Path(__file__).resolve().parents[2] / "leaderboard"
ENTRY_VERSION = 2
# Row kinds whose figure is an attacker's: "restorer" figures (PSNR, SSIM) and "reader" figures
# (plate accuracy: readers on the sensor image and chains on a restorer's output).
ATTACKER_KINDS = {"restorer": ("restorer",), "reader": ("reader", "chain")}


@dataclasses.dataclass(frozen=True)
class Stat:
    """One metric of one attack chain over its seeds: mean and std (ddof=1; 0 for one seed) of the
    seeds that have it, per-seed values (None where a seed had nothing to score) and the 95 %
    interval (low, high) where the rows carry one: with several seeds, the envelope of theirs."""

    mean: float
    std: float
    values: tuple[float | None, ...]
    interval: tuple[float, float] | None = None


@dataclasses.dataclass(frozen=True)
class Chain:
    """The rows of one attack chain (or lens / utility / bound) of an entry, summarised over seeds."""

    attack: str
    kind: str
    threat_model: str | None
    seeds: tuple[int, ...]
    metrics: dict[str, Stat]
    notes: dict[str, str]
    rows: tuple[Row, ...]


@dataclasses.dataclass
class Entry:
    """A leaderboard entry (format version 2); see the module docstring."""

    lens: str
    profile: str
    scenes: str
    seeds: list[int]
    profile_values: dict[str, Any]
    coefficients_um: list[float] | None
    lens_spec: dict[str, Any] | None
    rows: list[Row]
    settings: dict[str, Any] = dataclasses.field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        rows, unit_ids = _shared_unit_ids([r.to_json() for r in self.rows])
        return {"entry_version": ENTRY_VERSION, "lens": self.lens, "profile": self.profile, "scenes": self.scenes,
                "seeds": self.seeds, "profile_values": self.profile_values, "coefficients_um": self.coefficients_um,
                "lens_spec": self.lens_spec, "settings": self.settings, "rows": rows,
                **({"unit_ids": unit_ids} if unit_ids else {})}

    @classmethod
    def from_json(cls, d: Any) -> Entry:
        """An entry of any known version (1 is migrated); errors name the field, the value and what
        would be valid (``benchmark.results.entry_checks``)."""
        version = d.get("entry_version") if isinstance(d, dict) else None
        if version == 1:
            d = migrate_entry(d)
        elif isinstance(d, dict) and version != ENTRY_VERSION:
            raise ValueError(f"leaderboard entry_version {version!r} is not one this code reads (1, {ENTRY_VERSION})")
        check_entry_json(d)
        rows = []
        for i, row in enumerate(_expand_unit_ids(d["rows"], d.get("unit_ids") or {})):
            try:
                rows.append(Row.from_json(row))
            except (ValueError, TypeError, KeyError, AttributeError) as exc:  # a field of the wrong type
                raise ValueError(f"rows[{i}]: {exc}") from exc
        entry = cls(lens=d["lens"], profile=d["profile"], scenes=d["scenes"], seeds=list(d["seeds"]),
                    profile_values=d["profile_values"], coefficients_um=d.get("coefficients_um"),
                    lens_spec=d.get("lens_spec"), rows=rows, settings=dict(d.get("settings") or {}))
        entry.check()
        return entry

    def check(self) -> None:
        """Raise ValueError naming the row and field when a row is not the entry's, a metric is out of its
        range or the per-unit outcomes contradict the rows (``benchmark.results.entry_checks``)."""
        check_rows(self.rows, self.lens, self.profile, self.scenes, self.seeds)
        check_units(self.rows)

    def chains(self) -> list[Chain]:
        """One summary per attack chain, in the order the rows first name them (failed rows left out)."""
        return list(self._chains)

    @functools.cached_property
    def _chains(self) -> tuple[Chain, ...]:
        by_attack: dict[str, list[Row]] = {}
        for row in self.rows:
            if row.ok:
                by_attack.setdefault(row.attack, []).append(row)
        return tuple(_summarise(attack, rows) for attack, rows in by_attack.items())

    def chain(self, attack: str) -> Chain | None:
        return next((c for c in self.chains() if c.attack == attack), None)

    def metric(self, attack: str, name: str) -> Stat | None:
        """The metric `name` of the chain `attack` (e.g. "utility", "miou"), or None."""
        found = self.chain(attack)
        return None if found is None else found.metrics.get(name)

    def worst_case(self, name: str, kind: str, attacks: set[str] | None = None) -> tuple[Stat, str] | None:
        """The strongest attacker's figure over all its seeds: (stat, attack) or None. Among the
        chains of one kind ("restorer": restorers' PSNR/SSIM, "reader": readers and chains' plate
        accuracy) that have `name` (and are in `attacks` when given), the strongest is the one with
        the highest mean on the seeds every one of them has a value for, so that a chain run at
        seed 0 only is ranked against the others' seed 0, never against their mean over seeds;
        with no such seed, the highest mean. Ties go to the chain named first."""
        found = [(chain.metrics[name], chain.attack, _seed_values(chain.seeds, chain.metrics[name]))
                 for chain in self.chains()
                 if chain.kind in ATTACKER_KINDS[kind] and name in chain.metrics
                 and (attacks is None or chain.attack in attacks)]
        if not found:
            return None
        shared = set.intersection(*(set(values) for _, _, values in found))

        def rank(item: tuple[Stat, str, dict[int, float]]) -> float:
            stat, _, values = item
            return sum(values[s] for s in shared) / len(shared) if shared else stat.mean

        stat, attack, _ = max(found, key=rank)  # the first of equal maxima: ties go to the chain named first
        return stat, attack

    def failed(self) -> list[Row]:
        return [r for r in self.rows if not r.ok]

    def trainer_versions(self, kinds: Sequence[str] = ("lens", "utility")) -> set[str | None]:
        """The co-design trainer versions noted on the rows of `kinds` (None: not noted, i.e. rows
        published before the note existed, or rows no trainer made)."""
        return {row.notes.get("trainer_version") for row in self.rows if row.kind in kinds}

    def units(self, attack: str, seed: int) -> Units | None:
        """The per-unit outcomes of chain `attack` at `seed`, or None (no such ok row, or it has none)."""
        return next((r.units for r in self.rows if r.ok and r.attack == attack and r.seed == seed), None)


def _seed_values(seeds: Sequence[int], stat: Stat) -> dict[int, float]:
    """seed -> value of `stat` at that seed, for the seeds that have one."""
    return {s: v for s, v in zip(seeds, stat.values) if v is not None}


def _ids_key(ids: list[str]) -> str:
    return hashlib.sha256("\n".join(ids).encode()).hexdigest()[:12]


def _shared_unit_ids(rows: list[dict[str, Any]]) -> tuple[list[dict[str, Any]], dict[str, list[str]]]:
    """Rows (as JSON) with each ``units.ids`` list replaced by its key, and key -> ids."""
    shared: dict[str, list[str]] = {}
    for row in rows:
        units = row.get("units")
        if units is not None:
            key = _ids_key(units["ids"])
            shared[key] = units["ids"]
            row["units"] = {**units, "ids": key}
    return rows, shared


def _expand_unit_ids(rows: list[dict[str, Any]], shared: dict[str, list[str]]) -> list[dict[str, Any]]:
    """Inverse of ``_shared_unit_ids``; a key the entry does not hold is an error naming it."""
    out = []
    for row in rows:
        units = row.get("units")
        if units is not None and isinstance(units.get("ids"), str):
            if units["ids"] not in shared:
                raise ValueError(f"row {row.get('lens')}/{row.get('attack')} seed {row.get('seed')} points at unit ids "
                                 f"{units['ids']!r} that the entry's unit_ids do not hold")
            row = {**row, "units": {**units, "ids": shared[units["ids"]]}}
        out.append(row)
    return out


def _summarise(attack: str, rows: list[Row]) -> Chain:
    rows = sorted(rows, key=lambda r: r.seed)
    names = list(dict.fromkeys(name for r in rows for name in r.metrics))
    metrics = {}
    for name in names:
        values = [r.metric(name) for r in rows]
        valid = np.array([v for v in values if v is not None], dtype=float)
        intervals = [i for r in rows if (i := r.interval(name)) is not None]
        interval = (min(i[0] for i in intervals), max(i[1] for i in intervals)) if intervals else None
        metrics[name] = Stat(float(valid.mean()), float(valid.std(ddof=1)) if len(valid) > 1 else 0.0,
                             tuple(values), interval)
    notes = {k: v for r in reversed(rows) for k, v in r.notes.items()}
    threat = next((r.threat_model for r in rows if r.threat_model), None)
    return Chain(attack, rows[0].kind, threat, tuple(r.seed for r in rows), metrics, notes, tuple(rows))


def file_safe(name: str) -> str:
    """`name` as part of a file name: every character but letters, digits, "-", "_" and "." as "_" (a
    lens given as a spec path, `lenses/specs/defocus.toml`, is `lenses_specs_defocus.toml`)."""
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in name)


def entry_name(lens: str, profile: str, scenes: str) -> str:
    return f"{file_safe(lens)}__{file_safe(profile)}__{file_safe(scenes)}.json"


# ---- version 1 -> 2 ---------------------------------------------------------------------------------

def migrate_entry(old: dict[str, Any]) -> dict[str, Any]:
    """A version-1 entry as a version-2 dict: each chain's per-seed values become one Row per seed.

    Kinds come from ``schema.infer_legacy_kind`` on the chain's metric names over all its seeds (a
    reader's seed without a readable plate has no plate_acc, yet is a reader's row). The per-seed
    ``wall_s`` moves to the row's provenance; a row merged from an older run keeps that run's provenance.
    """
    if old.get("entry_version") != 1:
        raise ValueError(f"migrate_entry reads version-1 entries, got entry_version {old.get('entry_version')!r}")
    rows = []
    for item in old["rows"]:
        kind, restorer, reader = infer_legacy_kind(item["attack"], item["metrics"])
        provenance = {k: v for k, v in item.get("provenance", old["provenance"]).items() if v is not None}
        for i, seed in enumerate(item["seeds"]):
            values = {name: stats["values"][i] for name, stats in item["metrics"].items()}
            seed_provenance = dict(provenance)
            if values.get("wall_s") is not None:
                seed_provenance["wall_s"] = values["wall_s"]
            metrics = {name: v for name, v in values.items()
                       if v is not None and name not in LEGACY_PROVENANCE and math.isfinite(v)}
            row = Row(kind=kind, lens=old["lens"], attack=item["attack"], seed=int(seed), profile=old["profile"],
                      scenes=old["scenes"], restorer=restorer, reader=reader, metrics=metrics,
                      threat_model=item.get("threat_model"),
                      notes={"bound_assumptions": item["assumptions"]} if item.get("assumptions") else {},
                      provenance={**seed_provenance, "legacy_config_hashes": old["config_hashes"]})
            rows.append(row.to_json())
    return {"entry_version": ENTRY_VERSION, "lens": old["lens"], "profile": old["profile"], "scenes": old["scenes"],
            "seeds": old["seeds"], "profile_values": old["profile_values"], "coefficients_um": old["coefficients_um"],
            "lens_spec": old["lens_spec"], "settings": {}, "rows": rows}


def migrate_directory(directory: Path = LEADERBOARD) -> list[Path]:
    """Rewrite every stored entry of `directory`/entries that is older than ENTRY_VERSION; returns those.
    Holds the leaderboard's lock (a publish must not merge into an entry being rewritten)."""
    rewritten = []
    with locked(directory):
        for path in sorted((directory / "entries").glob("*.json")):
            raw = json.loads(path.read_text())
            if raw.get("entry_version") != ENTRY_VERSION:
                write_entry(path, Entry.from_json(raw))
                rewritten.append(path)
    return rewritten


# ---- reading and writing -------------------------------------------------------------------------

# The leaderboard folder's lock file (ignored by git): publishing, migrating and rendering
# read entries, then write entries or pages from them, and must not interleave.
LOCK_FILE = ".publish.lock"
_held = threading.local()  # the leaderboards this thread holds the lock of (a flock is not reentrant)


@contextlib.contextmanager
def locked(directory: Path) -> Iterator[None]:
    """Hold the lock of the leaderboard in `directory` (a kernel file lock, released when its holder
    dies); waits for it. Reentrant within a thread, so that a publish holding it can render."""
    key = str(Path(directory).resolve())
    held: set[str] = _held.__dict__.setdefault("paths", set())
    if key in held:
        yield
        return
    with exclusive(Path(directory) / LOCK_FILE):
        held.add(key)
        try:
            yield
        finally:
            held.discard(key)


def write_entry(path: Path, entry: Entry) -> Path:
    """Write `entry` to `path` after checking it, so that publishing never stores what reading refuses."""
    data = entry.to_json()
    try:
        check_entry_json(json.loads(json.dumps(data)))  # as a reader will see it: tuples become lists
        entry.check()
    except ValueError as exc:
        raise ValueError(f"{path}: refusing to write an invalid leaderboard entry: {exc}") from exc
    atomic_write_text(path, dumps_compact(data, sort_keys=True) + "\n")
    return path


def read_entry(path: Path) -> Entry:
    """The entry stored at `path`; errors name the file, the field and what would be valid."""
    try:
        return Entry.from_json(json.loads(Path(path).read_text()))
    except (ValueError, KeyError, TypeError, AttributeError) as exc:
        raise ValueError(f"{path}: not a valid leaderboard entry: {exc}") from exc


def load_entries(directory: Path = LEADERBOARD) -> list[Entry]:
    """Every entry of `directory`/entries, in file-name order; errors name the file."""
    return [read_entry(path) for path in sorted((directory / "entries").glob("*.json"))]


def display_order(entries: Sequence[Entry]) -> list[Entry]:
    """Entries as the tables list them: lenses first, the `sharp` reference last."""
    return [e for e in entries if e.lens != "sharp"] + [e for e in entries if e.lens == "sharp"]


def make_entry(lens: str, rows: Sequence[Row], profile: dict[str, Any], coefficients_um: list[float] | None,
               spec: dict[str, Any] | None, settings: dict[str, Any] | None = None) -> Entry:
    """The entry of one lens from its rows of one run (every seed, every chain, failed rows too)."""
    first = rows[0]
    used = {r.settings_hash for r in rows}
    # Through JSON: a stored entry has lists where a fresh one has tuples (image sizes).
    profile, spec = json.loads(json.dumps(profile)), json.loads(json.dumps(spec))
    return Entry(lens=lens, profile=first.profile, scenes=first.scenes, seeds=sorted({r.seed for r in rows}),
                 profile_values=profile, coefficients_um=coefficients_um, lens_spec=spec,
                 rows=[Row.from_json(json.loads(json.dumps(r.to_json()))) for r in rows],
                 settings={k: v for k, v in (settings or {}).items() if k in used})
