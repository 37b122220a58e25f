"""Entry-point discovery shared by the lens and attacker registries (one discovery path).

Built-in and third-party plugins register the same way: an entry point in a group such as
``privacy_lens_bench.lenses`` or ``privacy_lens_bench.attacks``. Discovery reads installed
metadata only and imports nothing, so a broken plugin costs nothing until it is asked for.
"""

from __future__ import annotations

import difflib
from importlib.metadata import EntryPoint, entry_points

__all__ = ["DuplicateNameError", "discover", "similar", "source_of", "suggest"]


class DuplicateNameError(RuntimeError):
    """Two installed distributions register the same plugin name in one group."""


def source_of(ep: EntryPoint) -> str:
    """Human-readable origin of an entry point: ``'<distribution> <version> (module:attr)'``."""
    dist = ep.dist
    where = f"{dist.name} {dist.version}" if dist is not None else "<unknown distribution>"
    return f"{where} ({ep.value})"


def discover(group: str) -> dict[str, EntryPoint]:
    """All entry points of ``group`` from every installed distribution, by name, unloaded.

    Raises:
        DuplicateNameError: Two distributions register the same name; the message names both.
    """
    found: dict[str, EntryPoint] = {}
    for ep in entry_points(group=group):
        if ep.name in found:
            raise DuplicateNameError(
                f"{group}: name {ep.name!r} is registered twice, by {source_of(found[ep.name])} "
                f"and by {source_of(ep)}; uninstall or rename one of them"
            )
        found[ep.name] = ep
    return found


def similar(name: str, choices: list[str] | set[str] | dict[str, object]) -> list[str]:
    """Up to three of ``choices`` that look like ``name``: close spellings (difflib) first,
    then names that contain ``name`` or start with it (so "wiener" finds "wiener-known-psf")."""
    pool = sorted(choices)
    close = difflib.get_close_matches(name, pool, n=3, cutoff=0.6)
    partial = [c for c in pool if c not in close and name and (name in c or c.startswith(name))]
    return (close + partial)[:3]


def suggest(name: str, choices: list[str] | set[str] | dict[str, object]) -> str:
    """A ' Did you mean ...?' hint for an unknown name (empty string when nothing is close)."""
    close = similar(name, choices)
    return f" Did you mean {', '.join(map(repr, close))}?" if close else ""
