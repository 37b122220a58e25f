"""One version per board: which entries the leaderboard compares, and which it shows apart.

A row's version is what computed it: its code version (``benchmark.store.provenance.code_version``,
stamped in every row's provenance; rows made before that carry their git commit only, see
``stamp_code_versions``), its torch version and its plate definition (the width plates are scored and
counted readable from: a run's settings ``plates_px``; runs before it counted every plate from 32 px).

Per profile, the board's version is the version of its newest row (by date). An entry every row of which
is of that version is on the board; any other entry is shown apart, marked with what differs, and enters
no takeaway, Pareto front, finding, chart or headline table (a re-publish brings it back).
"""

from __future__ import annotations

import dataclasses
import subprocess
import tarfile
import tempfile
from collections.abc import Sequence
from pathlib import Path

from benchmark.results.entries import Entry
from benchmark.results.schema import Row

__all__ = ["Apart", "Board", "Version", "board_split", "entry_versions", "row_version", "stamp_code_versions"]

LEGACY_PLATES = "every plate from 32 px (no per-plate widths)"
_FIELDS = ("code", "torch", "plates")


@dataclasses.dataclass(frozen=True, order=True)
class Version:
    """What computed a row: code version (or ``commit <hash>`` where none was stamped), torch, plates."""

    code: str
    torch: str
    plates: str

    def shown(self, name: str) -> str:
        """A field as the board shows it: a code version as its digest ("SHA-256 ..."), an unstamped one as
        such (its commit had uncommitted changes, so what ran is unknown)."""
        value = getattr(self, name)
        if name != "code":
            return value
        return "not stamped (run from uncommitted changes)" if value.startswith("commit ") else f"SHA-256 {value}"


def _differences(versions: Sequence[Version], board: Version, fields: Sequence[str]) -> str:
    """How `versions` differ from `board` in `fields`, each field once: "code a / b, torch 2.15.0 (board: code c,
    torch 2.14.1)"."""
    mine = []
    for name in fields:
        values = dict.fromkeys(v.shown(name) for v in versions if getattr(v, name) != getattr(board, name))
        mine.append(f"{name} {' / '.join(values)}")
    theirs = ", ".join(f"{name} {board.shown(name)}" for name in fields)
    return f"{', '.join(mine)} (board: {theirs})"


def _torch(row: Row) -> str:
    packages = str(row.provenance.get("packages") or "")
    return next((p.split("=", 1)[1] for p in packages.split(";") if p.startswith("torch=")), "unknown")


def _plates(entry: Entry, row: Row) -> str:
    found = (entry.settings.get(row.settings_hash or "") or {}).get("plates_px")
    if not isinstance(found, dict):
        return LEGACY_PLATES
    return f"scored from {found.get('scored_from')} px, readable from {found.get('readable_from')} px"


def row_version(entry: Entry, row: Row) -> Version:
    code = row.provenance.get("code_version")
    commit = str(row.provenance.get("git_commit") or "unknown")
    return Version(str(code) if code else f"commit {commit[:12]}", _torch(row), _plates(entry, row))


def entry_versions(entry: Entry) -> set[Version]:
    return {row_version(entry, r) for r in entry.rows}


@dataclasses.dataclass(frozen=True)
class Apart:
    """An entry shown apart: its versions and, in words, how they differ from its board's."""

    entry: Entry
    versions: tuple[Version, ...]
    reason: str
    fields: tuple[str, ...] = ()  # which of code, torch, plates differ from the board's


@dataclasses.dataclass(frozen=True)
class Board:
    """The entries compared (`current`, display order kept), those shown apart, and each profile's version."""

    current: list[Entry]
    apart: list[Apart]
    versions: dict[str, Version]


def _newest(entries: Sequence[Entry]) -> Version | None:
    dated = [(str(r.provenance.get("date") or ""), row_version(e, r)) for e in entries for r in e.rows]
    return max(dated, key=lambda x: x[0])[1] if dated else None


def board_split(entries: Sequence[Entry]) -> Board:
    """Split `entries` into those of their profile's board version and those shown apart (module docstring)."""
    versions: dict[str, Version] = {}
    for profile in dict.fromkeys(e.profile for e in entries):
        newest = _newest([e for e in entries if e.profile == profile])
        if newest is not None:
            versions[profile] = newest
    current, apart = [], []
    for e in entries:
        mine, board = sorted(entry_versions(e)), versions.get(e.profile)
        if board is None or mine == [board]:
            current.append(e)
            continue
        fields = tuple(f for f in _FIELDS if any(getattr(v, f) != getattr(board, f) for v in mine))
        reason = (f"{len(mine)} versions in one entry; " if len(mine) > 1 else "") + _differences(mine, board, fields)
        apart.append(Apart(e, tuple(mine), reason, fields))
    return Board(current, apart, versions)


def _commit_digest(repo: Path, commit: str, packages: str) -> str | None:
    """The code version of `commit` of `repo` with `packages` (None where git cannot give the tree)."""
    from benchmark.store.provenance import code_digest

    with tempfile.TemporaryDirectory() as tmp:
        archive = Path(tmp) / "tree.tar"
        try:
            subprocess.run(["git", "archive", "-o", str(archive), commit, "lenses", "attacks", "benchmark"],
                           cwd=repo, check=True, capture_output=True, timeout=120)
        except (OSError, subprocess.SubprocessError):
            return None
        with tarfile.open(archive) as tar:
            tar.extractall(Path(tmp) / "tree", filter="data")
        return code_digest(Path(tmp) / "tree", packages=packages)


def stamp_code_versions(entry: Entry, repo: Path, known: dict[tuple[str, str], str | None] | None = None) -> int:
    """Stamp `code_version` (and ``code_version_from`` saying how) into the provenance of every row of
    `entry` made before rows carried it, computed from the row's git commit and packages by the same digest
    (``code_digest``); rows whose commit is dirty or unknown to `repo` stay as they are. Returns the number
    stamped. `known` memoises digests by (commit, packages) across entries."""
    known = {} if known is None else known
    stamped = 0
    for row in entry.rows:
        commit, packages = str(row.provenance.get("git_commit") or ""), str(row.provenance.get("packages") or "")
        if row.provenance.get("code_version") or not commit or commit.endswith("-dirty") or commit == "unknown":
            continue
        if (commit, packages) not in known:
            known[commit, packages] = _commit_digest(repo, commit, packages)
        digest = known[commit, packages]
        if digest is not None:
            row.provenance["code_version"] = digest
            row.provenance["code_version_from"] = "computed after the run from its git commit and packages"
            stamped += 1
    return stamped


def main() -> int:
    """``python -m benchmark.publish.versions``: stamp the code version into the published entries' rows that
    lack it (``stamp_code_versions``, from this repository's history), holding the leaderboard's lock."""
    from benchmark.results.entries import LEADERBOARD, locked, read_entry, write_entry

    repo, known, total = LEADERBOARD.parent, {}, 0
    with locked(LEADERBOARD):
        for path in sorted((LEADERBOARD / "entries").glob("*.json")):
            entry = read_entry(path)
            stamped = stamp_code_versions(entry, repo, known)
            if stamped:
                write_entry(path, entry)
            print(f"{path.name}: {stamped} of {len(entry.rows)} rows stamped")
            total += stamped
    print(f"{total} rows stamped; {sum(v is None for v in known.values())} commits not found")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
