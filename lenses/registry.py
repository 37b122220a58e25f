"""Entry-point discovery shared by the lens and attacker registries (one discovery path)."""

from __future__ import annotations

import difflib
from importlib.metadata import EntryPoint, entry_points


class DuplicateNameError(RuntimeError):
    """Two installed distributions register the same plugin name in one group."""


def discover(group: str) -> dict[str, EntryPoint]:
    """All entry points of `group` by name, without importing them.

    Raises DuplicateNameError naming both sources when two distributions register one name.
    """
    found: dict[str, EntryPoint] = {}
    for ep in entry_points(group=group):
        if ep.name in found and found[ep.name].value != ep.value:
            raise DuplicateNameError(
                f"plugin name {ep.name!r} in group {group!r} is registered twice: "
                f"{found[ep.name].value} and {ep.value}; rename one of them"
            )
        found[ep.name] = ep
    return found


def suggest(name: str, choices: list[str] | set[str] | dict, n: int = 3) -> str:
    """A ' Did you mean ...?' hint for an unknown name (empty string when nothing is close)."""
    close = difflib.get_close_matches(name, list(choices), n=n, cutoff=0.5)
    close += [c for c in choices if name and name in c and c not in close]
    return f" Did you mean {', '.join(repr(c) for c in close[:n])}?" if close else ""
