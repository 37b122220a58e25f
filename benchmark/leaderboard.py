"""The leaderboard: one JSON entry per (lens, profile, scenes), rendered into a table and charts.

Entries are written by `python -m benchmark run ... --publish` and never edited by hand; the
table (`leaderboard/README.md`) and the charts are rendered from the entries alone by
`python -m benchmark report`, so they regenerate identically.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd

from benchmark.cache import atomic_write_text

LEADERBOARD = Path(__file__).resolve().parent.parent / "leaderboard"
ENTRY_VERSION = 1
# Columns that identify a row or carry provenance rather than a measurement.
_NON_METRIC = {"lens", "attack", "seed", "profile", "scenes", "threat_model", "config_hash", "git_commit", "packages",
               "python", "device", "threads", "date", "bound_assumptions", "bound_plate_format"}
PROVENANCE = ("git_commit", "packages", "python", "device", "threads", "date")


def entry_name(lens: str, profile: str, scenes: str) -> str:
    safe = lambda s: "".join(c if c.isalnum() or c in "-_." else "_" for c in s)  # noqa: E731
    return f"{safe(lens)}__{safe(profile)}__{safe(scenes)}.json"


def aggregate(rows: list[dict]) -> list[dict]:
    """Rows of one lens grouped by attack chain: metric mean, std (ddof=1; 0 for one seed) and per-seed values.

    Seeds without a value (NaN: nothing to score) are left out of the mean and the std and kept as
    None in ``values``."""
    out = []
    df = pd.DataFrame(rows)
    for attack, group in df.groupby("attack", sort=False):
        item: dict = {"attack": attack, "seeds": sorted(int(s) for s in group["seed"].unique())}
        if "threat_model" in group and group["threat_model"].notna().any():
            item["threat_model"] = group["threat_model"].dropna().iloc[0]
        metrics = {}
        for col in group.columns:
            if col in _NON_METRIC:
                continue
            values = pd.to_numeric(group[col], errors="coerce")
            if values.notna().sum() == 0:
                continue
            v = values.to_numpy(dtype=float)
            valid = v[~np.isnan(v)]  # e.g. plate accuracy of a seed whose scenes hold no readable plate
            metrics[col] = {"mean": float(valid.mean()), "std": float(valid.std(ddof=1)) if len(valid) > 1 else 0.0,
                            "values": [None if math.isnan(x) else float(x) for x in v]}
        item["metrics"] = metrics
        assumptions = group["bound_assumptions"].dropna() if "bound_assumptions" in group else []
        if len(assumptions):
            item["assumptions"] = assumptions.iloc[0]
        out.append(item)
    return out


def make_entry(lens: str, rows: list[dict], profile: dict, coefficients_um: list[float] | None,
               spec: dict | None) -> dict:
    first = rows[0]
    return {
        "entry_version": ENTRY_VERSION,
        "lens": lens,
        "profile": first["profile"],
        "scenes": first["scenes"],
        "seeds": sorted({int(r["seed"]) for r in rows}),
        "profile_values": profile,
        "coefficients_um": coefficients_um,
        "lens_spec": spec,
        "rows": aggregate(rows),
        "config_hashes": sorted({r["config_hash"] for r in rows}),
        "provenance": {k: first.get(k) for k in PROVENANCE},
    }


def publish(rows: list[dict], profile: dict, lens_info: dict[str, dict], directory: Path = LEADERBOARD) -> list[Path]:
    """Write one entry per lens of a run's rows (the `sharp` reference included).

    An existing entry of the same (lens, profile, scenes) is merged, not overwritten, when it
    was measured with the same profile values and lens (coefficients and spec of the first
    seed): rows of attack chains this run did not measure are kept with their own seeds, each
    stamped with the provenance of the run that measured it (``row["provenance"]``), so a run
    with fewer attackers (or more seeds for some of them) cannot erase a richer one; rows this
    run measured replace the stored ones. Otherwise the new entry replaces the old one.
    """
    paths = []
    for lens in dict.fromkeys(r["lens"] for r in rows):
        lens_rows = [r for r in rows if r["lens"] == lens]
        info = lens_info.get(lens, {})
        # Through JSON first: a stored entry has lists where a fresh one has tuples (image sizes).
        entry = json.loads(json.dumps(make_entry(lens, lens_rows, profile, info.get("coefficients_um"),
                                                 info.get("spec"))))
        path = directory / "entries" / entry_name(lens, entry["profile"], entry["scenes"])
        if path.exists():
            entry = merge_entries(json.loads(path.read_text()), entry)
        atomic_write_text(path, json.dumps(entry, indent=1, sort_keys=True) + "\n")
        paths.append(path)
    return paths


_SAME_MEASUREMENT = ("profile_values", "coefficients_um", "lens_spec")


def merge_entries(old: dict, new: dict) -> dict:
    """``new`` plus the rows of ``old`` whose attack chain ``new`` lacks, if both measured the same thing."""
    if any(old.get(k) != new.get(k) for k in _SAME_MEASUREMENT):
        return new
    have = {row["attack"] for row in new["rows"]}
    kept = [{**row, "provenance": row.get("provenance", old["provenance"])}
            for row in old["rows"] if row["attack"] not in have]
    if not kept:
        return new
    hashes = sorted(set(new["config_hashes"]) | set(old["config_hashes"]))
    seeds = sorted({s for row in new["rows"] + kept for s in row["seeds"]})
    return {**new, "rows": new["rows"] + kept, "config_hashes": hashes, "seeds": seeds}


def load_entries(directory: Path = LEADERBOARD) -> list[dict]:
    return [json.loads(p.read_text()) for p in sorted((directory / "entries").glob("*.json"))]


def metric(entry: dict, attack: str, name: str) -> tuple[float, float] | None:
    """(mean, std) of `name` in the row `attack` of an entry, or None."""
    for row in entry["rows"]:
        if row["attack"] == attack and name in row["metrics"]:
            m = row["metrics"][name]
            return m["mean"], m["std"]
    return None


def worst_case(entry: dict, name: str, kind: str) -> tuple[float, float, str] | None:
    """Highest mean of `name` over the attack rows of one kind ("restorer": PSNR/SSIM rows, "reader":
    plate rows): (mean, std, attack) of the strongest attacker."""
    best = None
    for row in entry["rows"]:
        if row["attack"] in ("lens", "utility", "bound") or name not in row["metrics"]:
            continue
        is_reader = "plate_acc" in row["metrics"]
        if (kind == "reader") != is_reader:
            continue
        m = row["metrics"][name]
        if best is None or m["mean"] > best[0]:
            best = (m["mean"], m["std"], row["attack"])
    return best
