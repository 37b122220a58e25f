"""The typed results schema: one `Row` per lens x attack chain x seed, and the results file.

Tables, charts, the leaderboard, the regression tests and users' scripts read rows only through
this module, so a row's meaning is written down once::

    from benchmark.results.schema import read_results, rows_of_kind
    results = read_results("runs/x/results.json")
    for row in rows_of_kind(results.rows, "restorer"):
        print(row.lens, row.attack, row.metric("psnr_db"), row.interval("psnr_db"))
        print(results.settings[row.settings_hash])   # the lens and attacker settings behind it

A row's `kind` is explicit: `lens` (the lens itself: PSF size, speed), `utility` (segmentation
of the sensor image), `bound` (the attack-independent privacy bound), `restorer` (one deblurring
attacker), `reader` (one plate reader on the sensor image), `chain` (a reader on a restorer's
output, attack `restorer>reader`), `reference` (a reference measurement such as the uncorrected
`raw` image). Rows measured on the sharp scene itself have lens `sharp`. A failed attacker is a
row with status `failed`, its error, and no metric.

A row may carry its per-unit outcomes (`units`, see `Units`): the value of each scene or plate
it was scored on, keyed by ids that are the same for every lens of the same profile, scene set and
seed, so that two lenses are compared on the same scenes and plates (benchmark.publish.findings).

Notes with a meaning the suite reads (``Row.notes``, all strings): ``trainer_version`` (the co-design
trainer that made a lens or utility row), ``FIT_STILL_RISING`` = "fit_still_rising" ("true" / "false"):
set by a learned attacker whose fit stopped while its held-out score was still improving; such a
row's figures are a lower bound on that attacker, and the leaderboard flags it
(benchmark.results.attack_gap).

Version history of results.json: 1 = flat rows (kind inferred from the attack's name), migrated
by `migrate_legacy_row`; 2 = this schema (`units` is optional: rows written before it existed
read with `units` None, "no per-unit outcomes").
"""

from __future__ import annotations

import dataclasses
import gzip
import json
import math
import re
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from benchmark.store.cache import atomic_write_text, config_hash

__all__ = [
    "FIT_STILL_RISING",
    "KINDS",
    "LEGACY_PROVENANCE",
    "SCHEMA_VERSION",
    "SHARP_LENS",
    "STAGES",
    "UNIT_KINDS",
    "Results",
    "Row",
    "RowError",
    "Units",
    "dumps_compact",
    "infer_legacy_kind",
    "migrate_legacy_row",
    "ok_rows",
    "read_results",
    "rows_of_kind",
    "settings_hash",
    "threat_models",
    "write_results",
]

SCHEMA_VERSION = 2
KINDS = ("lens", "utility", "bound", "restorer", "reader", "chain", "reference")
STATUSES = ("ok", "failed")
# Where a row can fail: an attacker's stages, and "measure" for the suite's own measurements
# (e.g. the bound running past its budget). A failed row names one of these.
STAGES = ("load", "fit", "restore", "read", "score", "measure")
SHARP_LENS = "sharp"
# The note a learned attacker's row carries when its fit stopped while still improving ("true"/"false").
FIT_STILL_RISING = "fit_still_rising"
LEARNS = "learns"  # note: "true" when the row's attacker (or a part of its chain) fits weights to data (Attack.learns)
CHAIN_SEPARATOR = ">"
# Kinds whose `attack` is the kind itself (no attacker involved).
_SELF_NAMED = ("lens", "utility", "bound")
CASCADE_PREFIX = "cascade:"  # a reader row's attack "cascade:<reader>": the reader run as a cascade
LEGACY_PROVENANCE = ("git_commit", "packages", "python", "device", "threads", "date", "wall_s")
# String-valued facts of a legacy flat row that are neither metrics nor provenance.
_LEGACY_NOTES = ("bound_assumptions", "bound_plate_format")
_LEGACY_IDS = ("lens", "attack", "seed", "profile", "scenes", "config_hash", "threat_model")


@dataclasses.dataclass(frozen=True)
class RowError:
    """Why a row failed: the attacker (or task) that failed, the stage and the message."""

    attacker: str
    stage: str
    message: str

    def __post_init__(self) -> None:
        if self.stage not in STAGES:
            raise ValueError(f"RowError.stage {self.stage!r} is not one of {STAGES}")

    def to_json(self) -> dict[str, str]:
        return dataclasses.asdict(self)


UNIT_KINDS = ("scene", "plate")
# Per-unit floats are stored to this many decimals (PSNR to 1e-4 dB, SSIM to 1e-4): far below any
# difference a paired test can resolve, and it keeps the committed leaderboard entries small.
UNIT_DECIMALS = 4


@dataclasses.dataclass(frozen=True)
class Units:
    """Per-unit outcomes of one row: what each scene or plate scored, in a stable order.

    Attributes:
        unit: "scene" (restorer and utility rows: one val scene each) or "plate" (reader and chain
            rows: one readable plate each).
        prefix: Common prefix of the unit names (e.g. "synthetic/val/0/"), stored once.
        ids: The rest of each unit's name: ``prefix + id`` is the scene's name (``Scene.name``,
            deterministic from scene set, split, run seed and index, whatever the lens), and for a
            plate ``{scene name}#{k}``, the k-th readable plate of that scene (or plate window).
        values: Name -> one value per id: floats rounded to UNIT_DECIMALS (``psnr_db``, ``ssim``),
            ints (plates: ``correct`` 0/1, ``char_errors`` = edit distance to the truth), or per
            scene one int per class (utility: ``intersection``, ``union`` pixel counts, from which
            the pooled mIoU of any subset of scenes is recomputed exactly).
    """

    unit: str
    prefix: str
    ids: tuple[str, ...]
    values: dict[str, tuple[Any, ...]]

    def __post_init__(self) -> None:
        if self.unit not in UNIT_KINDS:
            raise ValueError(f"Units.unit {self.unit!r} is not one of {UNIT_KINDS}")
        object.__setattr__(self, "ids", tuple(str(i) for i in self.ids))
        if len(set(self.ids)) != len(self.ids):
            raise ValueError(f"Units ids must be unique, got {len(self.ids) - len(set(self.ids))} duplicate(s)")
        values = {}
        for name, column in self.values.items():
            column = tuple(_unit_value(name, v) for v in column)
            if len(column) != len(self.ids):
                raise ValueError(f"Units value {name!r} has {len(column)} entries for {len(self.ids)} ids")
            values[str(name)] = column
        object.__setattr__(self, "values", values)

    @classmethod
    def from_names(cls, unit: str, names: Sequence[str], values: Mapping[str, Sequence[Any]]) -> Units:
        """Units of the full unit names `names` (their common prefix up to a "/" is factored out)."""
        prefix = _common_prefix(names)
        return cls(unit, prefix, tuple(n[len(prefix):] for n in names), {k: tuple(v) for k, v in values.items()})

    def names(self) -> tuple[str, ...]:
        """The full unit names (prefix + id), the keys units are paired by."""
        return tuple(self.prefix + i for i in self.ids)

    def to_json(self) -> dict[str, Any]:
        return {"unit": self.unit, "prefix": self.prefix, "ids": list(self.ids),
                "values": {k: [list(v) if isinstance(v, tuple) else v for v in col] for k, col in self.values.items()}}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Units:
        missing = {"unit", "prefix", "ids", "values"} - set(d)
        if missing:
            raise ValueError(f"units lack field(s) {sorted(missing)}")
        return cls(str(d["unit"]), str(d["prefix"]), tuple(d["ids"]), {k: tuple(v) for k, v in d["values"].items()})


def _unit_value(name: str, value: Any) -> Any:
    """A per-unit value as stored: an int stays an int, a float is rounded, a list becomes a tuple of ints."""
    if isinstance(value, (list, tuple)):
        if not all(isinstance(v, int) and not isinstance(v, bool) for v in value):
            raise ValueError(f"Units value {name!r}: a per-unit list must hold ints (counts), got {value!r:.80}")
        return tuple(value)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"Units value {name!r} must be a number or a list of counts, got {value!r:.80}")
    if isinstance(value, int):
        return value
    if not math.isfinite(value):
        raise ValueError(f"Units value {name!r} is {value}; leave a unit that cannot be scored out instead")
    return round(float(value), UNIT_DECIMALS)


def _common_prefix(names: Sequence[str]) -> str:
    """The longest common prefix of `names` that ends at a "/" ("" when there is none)."""
    if not names:
        return ""
    first, last = min(names), max(names)
    n = 0
    while n < min(len(first), len(last)) and first[n] == last[n]:
        n += 1
    return first[:first.rfind("/", 0, n) + 1] if n else ""


# Arrays of numbers that json.dumps(indent=...) spread over lines: only whitespace, digits, signs,
# points, exponents and commas between brackets, starting with a line break (a JSON string never
# holds a raw line break, so no string is touched).
_NUMBER_ARRAY = re.compile(r"\[\s*\n[\s0-9eE.+\-,]*\]")


def dumps_compact(obj: Any, **kwargs: Any) -> str:
    """``json.dumps(obj, indent=1, allow_nan=False, **kwargs)`` with every array of numbers on one line
    (per-unit outcomes would otherwise take one line per number)."""
    text = json.dumps(obj, indent=1, allow_nan=False, **kwargs)
    return _NUMBER_ARRAY.sub(lambda m: re.sub(r"\s+", "", m.group(0)), text)


@dataclasses.dataclass
class Row:
    """One result row (see the module docstring for the kinds).

    Attributes:
        kind: One of KINDS.
        lens: Lens name (`sharp` for rows measured on the sharp scenes).
        attack: The chain's name: the kind for lens/utility/bound, the attacker's name for
            restorer/reader/reference, `restorer>reader` for a chain.
        seed, profile, scenes: What was run.
        restorer, reader: The attackers of the row, where they apply, else None.
        status: "ok" or "failed"; a failed row has an `error` and no metric.
        metrics: Metric name -> finite float (psnr_db in dB, ssim, miou, plate_acc in [0, 1],
            fit_s in seconds, images_per_s, ...). A metric that cannot be measured is absent,
            never NaN or inf.
        intervals: Metric name -> (low, high), its 95 % interval.
        interval_methods: Metric name -> how the interval was computed ("wilson", "bootstrap").
        threat_model: The attacker's threat model (ThreatModel value), None for non-attack rows.
        notes: Name -> text, facts that are not numbers (e.g. the bound's assumptions).
        settings_hash: Key of the lens + attacker settings in results.json's "settings".
        provenance: code_version, git_commit, packages, python, device, threads, date, wall_s.
        units: Per-unit outcomes (per scene or per plate, see `Units`), or None when the row
            does not carry them (lens and bound rows; rows written before they existed).
    """

    kind: str
    lens: str
    attack: str
    seed: int
    profile: str
    scenes: str
    restorer: str | None = None
    reader: str | None = None
    status: str = "ok"
    error: RowError | None = None
    metrics: dict[str, float] = dataclasses.field(default_factory=dict)
    intervals: dict[str, tuple[float, float]] = dataclasses.field(default_factory=dict)
    interval_methods: dict[str, str] = dataclasses.field(default_factory=dict)
    threat_model: str | None = None
    notes: dict[str, str] = dataclasses.field(default_factory=dict)
    settings_hash: str = ""
    provenance: dict[str, Any] = dataclasses.field(default_factory=dict)
    units: Units | None = None

    def __post_init__(self) -> None:
        self.metrics = {str(k): _finite(k, v) for k, v in self.metrics.items()}
        self.intervals = {str(k): (float(v[0]), float(v[1])) for k, v in self.intervals.items()}
        self.validate()

    # ---- construction -------------------------------------------------------------------------

    @classmethod
    def failed(cls, kind: str, lens: str, attack: str, seed: int, profile: str, scenes: str, error: RowError,
               **fields: Any) -> Row:
        """A failed row: the error and no metric."""
        return cls(kind=kind, lens=lens, attack=attack, seed=seed, profile=profile, scenes=scenes,
                   status="failed", error=error, **fields)

    def validate(self) -> None:
        """Raise ValueError naming the field when the row breaks the schema."""
        if self.kind not in KINDS:
            raise ValueError(f"Row.kind {self.kind!r} is not one of {KINDS}")
        if self.status not in STATUSES:
            raise ValueError(f"Row.status {self.status!r} is not one of {STATUSES}")
        if self.status == "failed" and (self.error is None or self.metrics):
            raise ValueError(f"failed row {self.lens}/{self.attack}: needs an error and no metrics")
        if self.status == "ok" and self.error is not None:
            raise ValueError(f"row {self.lens}/{self.attack}: status ok with an error")
        if not isinstance(self.seed, int) or isinstance(self.seed, bool):
            raise ValueError(f"Row.seed must be an int, got {self.seed!r}")
        expected = {
            "restorer": (self.attack, None),
            "reader": (None, self.attack),
        }
        if self.kind in _SELF_NAMED:
            if self.attack != self.kind or self.restorer is not None or self.reader is not None:
                raise ValueError(f"a {self.kind} row has attack {self.kind!r} and no restorer/reader, "
                                 f"got attack={self.attack!r} restorer={self.restorer!r} reader={self.reader!r}")
        elif self.kind == "reader" and self.reader is not None and self.attack == cascade_name(self.reader):
            if self.restorer is not None:
                raise ValueError(f"a cascade reader row reads the sensor image: no restorer, got {self.restorer!r}")
        elif self.kind in expected:
            if (self.restorer, self.reader) != expected[self.kind]:
                raise ValueError(f"a {self.kind} row names its attacker in attack and {self.kind}, got "
                                 f"attack={self.attack!r} restorer={self.restorer!r} reader={self.reader!r}")
        elif self.kind == "chain":
            if self.restorer is None or self.reader is None or self.attack != chain_name(self.restorer, self.reader):
                raise ValueError(f"a chain row has attack 'restorer>reader' matching its fields, got "
                                 f"attack={self.attack!r} restorer={self.restorer!r} reader={self.reader!r}")
        for name in self.intervals:
            low, high = self.intervals[name]
            if not low <= high:
                raise ValueError(f"interval of {name!r} has low {low} > high {high}")
        if self.units is not None and not isinstance(self.units, Units):
            raise ValueError(f"Row.units must be a schema.Units or None, got {type(self.units).__name__}")
        if self.units is not None and self.status == "failed":
            raise ValueError(f"failed row {self.lens}/{self.attack}: carries no per-unit outcomes")

    # ---- reading ------------------------------------------------------------------------------

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    def metric(self, name: str, default: float | None = None) -> float | None:
        """The metric `name`, or `default` when this row does not have it (or failed)."""
        return self.metrics.get(name, default)

    def interval(self, name: str) -> tuple[float, float] | None:
        """The 95 % interval (low, high) of metric `name`, or None."""
        return self.intervals.get(name)

    def set_interval(self, name: str, low: float, high: float, method: str) -> None:
        """Attach the 95 % interval of metric `name` (which the row must have)."""
        if name not in self.metrics:
            raise KeyError(f"row {self.lens}/{self.attack} has no metric {name!r} to put an interval on")
        self.intervals[name] = (float(low), float(high))
        self.interval_methods[name] = method
        self.validate()

    def set_units(self, units: Units) -> None:
        """Attach the row's per-unit outcomes (scenes or plates, see `Units`)."""
        self.units = units
        self.validate()

    # ---- serialisation ------------------------------------------------------------------------

    def to_json(self) -> dict[str, Any]:
        """A JSON-serialisable dict (strict JSON: no NaN or inf)."""
        d = dataclasses.asdict(self)
        d["error"] = None if self.error is None else self.error.to_json()
        d["intervals"] = {k: list(v) for k, v in self.intervals.items()}
        d["units"] = None if self.units is None else self.units.to_json()
        return d

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Row:
        """Inverse of `to_json`; a missing required field or an unknown one raises ValueError naming it."""
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = set(d) - names
        if unknown:
            raise ValueError(f"row has unknown field(s) {sorted(unknown)}; valid: {sorted(names)}")
        missing = {"kind", "lens", "attack", "seed", "profile", "scenes"} - set(d)
        if missing:
            raise ValueError(f"row lacks required field(s) {sorted(missing)}")
        fields = dict(d)
        if fields.get("error") is not None:
            fields["error"] = RowError(**fields["error"])
        fields["intervals"] = {k: tuple(v) for k, v in (fields.get("intervals") or {}).items()}
        if fields.get("units") is not None:
            fields["units"] = Units.from_json(fields["units"])
        return cls(**fields)

    def flat(self) -> dict[str, Any]:
        """The row as one flat dict (ids, metrics, notes, provenance, status): for pandas tables."""
        out: dict[str, Any] = {"kind": self.kind, "lens": self.lens, "attack": self.attack, "restorer": self.restorer,
                               "reader": self.reader, "seed": self.seed, "profile": self.profile,
                               "scenes": self.scenes, "status": self.status, "threat_model": self.threat_model,
                               "settings_hash": self.settings_hash}
        if self.error is not None:
            out.update({f"error_{k}": v for k, v in self.error.to_json().items()})
        out.update(self.metrics)
        out.update(self.notes)
        out.update(self.provenance)
        return out


def chain_name(restorer: str, reader: str) -> str:
    """The attack name of a reader run on a restorer's output."""
    return f"{restorer}{CHAIN_SEPARATOR}{reader}"


def cascade_name(reader: str) -> str:
    """The attack name of a reader run as a cascade: last, on the plates no other chain read
    (benchmark.runner.cascade)."""
    return f"{CASCADE_PREFIX}{reader}"


def chain_parts(chain: str) -> list[str]:
    """The attackers a chain of the ensemble names: "restorer>reader" -> both, "cascade:reader" -> the reader."""
    return chain.removeprefix(CASCADE_PREFIX).split(">")


def threat_models(rows: Iterable[Row]) -> dict[str, str | None]:
    """Each attack of `rows` (one lens's) with its threat model: a chain's is the strongest of its
    restorer's, its reader's and its own rows' (`attacks.ThreatModel.strongest`; a chain needs what
    its strongest part needs), so rows written before chains were labelled so read right too.
    None for rows without one (lens, utility, bound)."""
    from attacks import ThreatModel  # lazy: reading rows needs no torch

    own: dict[str, set[str]] = {}
    parts: dict[str, tuple[str, str]] = {}
    for r in rows:
        own.setdefault(r.attack, set()).update([r.threat_model] if r.threat_model else [])
        if r.restorer is not None and r.reader is not None and r.attack == chain_name(r.restorer, r.reader):
            parts[r.attack] = (r.restorer, r.reader)
    out: dict[str, str | None] = {}
    for attack, models in own.items():
        found = set(models).union(*(own.get(p, set()) for p in parts.get(attack, ())))
        out[attack] = ThreatModel.strongest(*found).value if found else None
    return out


def _finite(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"metric {name!r} must be a number, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"metric {name!r} is {v}; a metric that cannot be measured is left out, never NaN/inf")
    return v


def rows_of_kind(rows: Iterable[Row], *kinds: str, ok_only: bool = True) -> list[Row]:
    """The rows of the given kinds (every kind when none is given); failed rows only if ok_only=False."""
    unknown = set(kinds) - set(KINDS)
    if unknown:
        raise ValueError(f"unknown row kind(s) {sorted(unknown)}; valid: {KINDS}")
    return [r for r in rows if (not kinds or r.kind in kinds) and (r.ok or not ok_only)]


def ok_rows(rows: Iterable[Row]) -> list[Row]:
    """The rows that carry measurements (status ok)."""
    return [r for r in rows if r.ok]


def settings_hash(settings: Mapping[str, Any]) -> str:
    """Key of a settings dict (lens spec, attacker `describe()`, profile, scenes, seed)."""
    return config_hash(settings)


# ---- the results file ---------------------------------------------------------------------------

@dataclasses.dataclass
class Results:
    """The content of a results.json: rows, the settings they point at, and run metadata."""

    rows: list[Row]
    settings: dict[str, dict[str, Any]] = dataclasses.field(default_factory=dict)
    meta: dict[str, Any] = dataclasses.field(default_factory=dict)
    schema_version: int = SCHEMA_VERSION

    def to_json(self) -> dict[str, Any]:
        missing = sorted({r.settings_hash for r in self.rows if r.settings_hash} - set(self.settings))
        if missing:
            raise ValueError(f"rows point at settings {missing} that the results do not carry")
        return {"schema_version": SCHEMA_VERSION, "meta": self.meta, "rows": [r.to_json() for r in self.rows],
                "settings": self.settings}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Results:
        """Read a results dict of any known version (1: flat rows, migrated)."""
        version = d.get("schema_version")
        if version == 1:
            rows = [migrate_legacy_row(r) for r in d["rows"]]
        elif version == SCHEMA_VERSION:
            rows = [Row.from_json(r) for r in d["rows"]]
        else:
            raise ValueError(f"results schema_version {version!r} is not one this code reads (1, {SCHEMA_VERSION})")
        return cls(rows, dict(d.get("settings") or {}), dict(d.get("meta") or {}), SCHEMA_VERSION)


def write_results(path: Path, results: Results) -> Path:
    """Write `results` to `path` (atomically, strict JSON)."""
    path = Path(path)
    atomic_write_text(path, dumps_compact(results.to_json(), default=str) + "\n")
    return path


def read_results(path: Path) -> Results:
    """Read a results.json of any known version, plain or gzipped (a name ending in ``.gz``); errors name
    the file."""
    path = Path(path)
    try:
        raw = path.read_bytes()
        return Results.from_json(json.loads(gzip.decompress(raw) if path.name.endswith(".gz") else raw))
    except (ValueError, KeyError, TypeError) as exc:
        raise ValueError(f"{path}: not a valid results file: {exc}") from exc


# ---- version 1 (flat rows) ------------------------------------------------------------------------

def infer_legacy_kind(attack: str, metric_names: Iterable[str]) -> tuple[str, str | None, str | None]:
    """(kind, restorer, reader) of a version-1 row from its attack name and metric names.

    The only place the old conventions survive: attack "lens"/"utility"/"bound" named the kind,
    "restorer>reader" a chain, and a row with plate metrics was a reader's.
    """
    if attack in _SELF_NAMED:
        return attack, None, None
    if CHAIN_SEPARATOR in attack:
        restorer, reader = attack.split(CHAIN_SEPARATOR, 1)
        return "chain", restorer, reader
    if "plate_acc" in set(metric_names):
        return "reader", None, attack
    return "restorer", attack, None


def migrate_legacy_row(d: Mapping[str, Any]) -> Row:
    """A version-1 flat row (ids, metrics, provenance side by side) as a `Row`.

    Non-finite metrics (NaN: nothing to score; inf from the old mean) are dropped.
    """
    missing = [k for k in ("lens", "attack", "seed", "profile", "scenes") if k not in d]
    if missing:
        raise ValueError(f"legacy row lacks {missing}: {dict(d)!r:.200}")
    metrics: dict[str, float] = {}
    for key, value in d.items():
        if key in _LEGACY_IDS or key in LEGACY_PROVENANCE or key in _LEGACY_NOTES:
            continue
        if isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value):
            metrics[key] = float(value)
    kind, restorer, reader = infer_legacy_kind(str(d["attack"]), d.keys())
    threat = d.get("threat_model")
    return Row(kind=kind, lens=str(d["lens"]), attack=str(d["attack"]), seed=int(d["seed"]),
               profile=str(d["profile"]), scenes=str(d["scenes"]), restorer=restorer, reader=reader,
               metrics=metrics, threat_model=threat if isinstance(threat, str) else None,
               notes={k: str(d[k]) for k in _LEGACY_NOTES if d.get(k) is not None},
               # Version 1 stored only a hash of the settings, not the settings: keep it as provenance.
               provenance={**{k: d[k] for k in LEGACY_PROVENANCE if k in d},
                           **({"legacy_config_hash": d["config_hash"]} if "config_hash" in d else {})})
