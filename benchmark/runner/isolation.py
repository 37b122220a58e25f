"""What keeps one attacker from reaching another's inputs, outputs, cache or run: private copies of what
it is handed, a cache folder of its own, and the failure boundary around every call into a plugin.

Torch has no read-only tensors, so every batch handed to an attacker is a copy it owns: a restorer
that writes into its input (``s.zero_()``) would otherwise change the sensor images every later
attacker sees, and a reader that writes into a restorer's output would change what the next reader
reads. What an attacker returns is checked and copied by the evaluation before it is kept, so the
attacker cannot change it afterwards either. Each attacker also gets its own fit context: its own
copy of the lens and of its co-design adversary (an attacker may move their parameters), and its own
cache folder, ``<cache>/attacks/<name>/`` (``attacker_folder``), which its ``cache_dir`` and
``artifacts`` point at (``OwnArtifacts``: it cannot name another attacker's artifacts through them).

The cache is on disk, which an attacker's code can reach anyway; so every call into a plugin that is
given the attack folder (``attempt(..., cache_root=)``) is checked afterwards (``CacheGuard``): a file of
another attacker's folder that existed before the call and was changed or removed by it fails the call's
row, naming the folders, and the changed files are removed, so their owner rebuilds them instead of
loading what another attacker wrote; a call that adds, changes or removes a file of the leaderboard
folder fails the same way (that folder is restored from git, not rebuilt). New cache files are not flagged (another run sharing the cache may be
creating its own); a run sharing the cache that replaces an existing artifact during the call (two runs
fitting the same key at once) trips it too, and a rerun passes.

A plugin call may also leave things running (``Leftovers``): the child processes it started and left
alive are ended when the call returns (SIGTERM, then SIGKILL; Linux, from ``/proc``), logged with the
attacker's name; threads cannot be stopped from outside, so the non-daemon ones it left are logged and
remembered (``stray_threads``), and the CLI ends the process without waiting for them once the run has
written its results.
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import logging
import os
import re
import signal
import threading
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, TypeVar

import torch

import attacks
from benchmark.runner.budget import time_budget
from benchmark.runner.sandbox import live_pids
from benchmark.results.entries import LEADERBOARD
from benchmark.results.schema import RowError
from benchmark.store.cache import ArtifactCache, config_hash, discard

log = logging.getLogger(__name__)
T = TypeVar("T")


def private(batch: torch.Tensor, device: str) -> torch.Tensor:
    """A copy of `batch` on `device` that shares no memory with it (what an attacker is handed)."""
    return batch.to(device, copy=True)


def attacker_folder(attacker: str) -> str:
    """The name of `attacker`'s cache folder: its name, or a hash of it where the name is not a safe
    folder name (a plugin named "../x" must not reach outside the attack folder)."""
    return attacker if re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9._-]*", attacker) else f"attacker-{config_hash(attacker)}"


class OwnArtifacts(ArtifactCache):
    """One attacker's artifact store inside the attack folder: `<root>/<attacker>/<config hash>.safetensors`
    for its own kind (where a run kept them before attackers had folders of their own), `<root>/<attacker>/
    <kind>/...` for any other kind it names, so none resolves into another attacker's folder."""

    def __init__(self, root: Path, attacker: str):
        super().__init__(Path(root) / attacker_folder(attacker))
        self.attacker = attacker

    def path(self, kind: str, key: Mapping[str, Any]) -> Path:
        folder = self.root if kind == self.attacker else self.root / attacker_folder(kind)
        return folder / f"{config_hash(dict(key))}{self.suffix}"


def own_context(ctx: attacks.FitContext, attacker: str) -> attacks.FitContext:
    """A fit context for `attacker`: its own copy of the lens and the adversary (one deep copy, so the
    copied lens still holds the copied adversary) and, where the run keeps a cache, its own folder of
    the attack folder `ctx.cache_dir` (``OwnArtifacts``). Training pairs need no copy: `train_pairs()`
    makes fresh tensors at every call (benchmark.runner.sensing.train_pairs_factory)."""
    lens, adversary = copy.deepcopy((ctx.lens, ctx.adversary))
    own: dict[str, Any] = {}
    if ctx.cache_dir is not None:
        own = {"cache_dir": Path(ctx.cache_dir) / attacker_folder(attacker),
               "artifacts": None if ctx.artifacts is None else OwnArtifacts(Path(ctx.cache_dir), attacker)}
    return dataclasses.replace(ctx, lens=lens, adversary=adversary, **own)


class CacheGuard:
    """The files of every other attacker's folder of an attack folder, as they were when it was made
    (inode, size, modification time), to tell which of them a plugin call changed or removed; and of
    the leaderboard folder, where a plugin call may change, remove or add nothing."""

    def __init__(self, root: Path | None, attacker: str, leaderboard: Path | None = LEADERBOARD):
        self.root = None if root is None else Path(root)
        self.own = attacker_folder(attacker)
        self.leaderboard = leaderboard
        self.before = self._state()
        self.board = _files(leaderboard)

    def _state(self) -> dict[str, tuple[int, int, int]]:
        state: dict[str, tuple[int, int, int]] = {}
        if self.root is None or not self.root.is_dir():
            return state
        for top in os.scandir(self.root):
            if top.name == self.own or not top.is_dir(follow_symlinks=False):
                continue
            state.update(_files(Path(top.path)))
        return state

    def changed(self) -> list[Path]:
        """The files of other attackers' folders that existed before and were changed or removed since."""
        after = self._state()
        return sorted(Path(p) for p, was in self.before.items() if after.get(p) != was)

    def board_changed(self) -> list[Path]:
        """The files of the leaderboard folder added, changed or removed since."""
        after = _files(self.leaderboard)
        return sorted(Path(p) for p in set(after) | set(self.board) if after.get(p) != self.board.get(p))

    def failure(self, attacker: str, stage: str) -> RowError | None:
        """None when nothing changed; else the RowError of `attacker` at `stage`, after removing the
        changed cache files and their checksums (logged as an error)."""
        board = self.board_changed()
        if board and self.leaderboard is not None:
            message = (f"changed {len(board)} file(s) of the leaderboard folder (e.g. "
                       f"{board[0].relative_to(self.leaderboard)}): an attacker may write only its own cache "
                       f"folder; restore the folder (git checkout -- {self.leaderboard.name}/) before publishing")
            log.error("attacker %r at %s: %s", attacker, stage, message)
            return RowError(attacker, stage, message)
        changed = self.changed()
        if not changed or self.root is None:
            return None
        for path in changed:
            discard(path.with_suffix("") if path.suffix == ".sha256" else path)
        owners = sorted({path.relative_to(self.root).parts[0] for path in changed})
        message = (f"changed {len(changed)} file(s) of the cache folder(s) of {', '.join(owners)} (an attacker may "
                   f"write only its own, {self.own}/; e.g. {changed[0].relative_to(self.root)}); they were "
                   "removed and their owner will rebuild them")
        log.error("attacker %r at %s: %s", attacker, stage, message)
        return RowError(attacker, stage, message)


def _files(folder: Path | None) -> dict[str, tuple[int, int, int]]:
    """(inode, size, modification time) of every file under `folder` (none when it is None or absent)."""
    state: dict[str, tuple[int, int, int]] = {}
    if folder is None:
        return state
    for where, _, files in os.walk(folder):
        for name in files:
            path = os.path.join(where, name)
            try:
                st = os.lstat(path)
            except FileNotFoundError:
                continue
            state[path] = (st.st_ino, st.st_size, st.st_mtime_ns)
    return state


_STRAY: list[tuple[str, threading.Thread]] = []  # (attacker, a non-daemon thread it left running)


def stray_threads() -> list[tuple[str, threading.Thread]]:
    """The non-daemon threads plugin calls left running that are still alive, with their attackers."""
    return [(a, t) for a, t in _STRAY if t.is_alive()]


def child_pids() -> set[int]:
    """This process's live child processes (Linux ``/proc``; empty where there is none)."""
    me, found = os.getpid(), set()
    try:
        entries = os.listdir("/proc")
    except OSError:
        return found
    for entry in entries:
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat", "rb") as f:
                stat = f.read().decode(errors="replace")
        except OSError:
            continue
        fields = stat[stat.rfind(")") + 2:].split()  # after "pid (comm) ": state, ppid, ...
        if len(fields) > 1 and fields[0] != "Z" and int(fields[1]) == me:
            found.add(int(entry))
    return found


def _end(pids: set[int], grace_s: float = 2.0) -> None:
    """SIGTERM `pids`, then SIGKILL whichever is still there after `grace_s`, reaping each (a child left
    unreaped stays a zombie for as long as this process lives)."""
    left = set(pids)
    for sig in (signal.SIGTERM, signal.SIGKILL):
        for pid in left:
            with contextlib.suppress(OSError):
                os.kill(pid, sig)
        deadline = time.monotonic() + grace_s
        while left and time.monotonic() < deadline:
            for pid in list(left):
                try:
                    if os.waitpid(pid, os.WNOHANG)[0]:
                        left.discard(pid)
                except ChildProcessError:  # reaped elsewhere (by its Popen)
                    left.discard(pid)
            if left:
                time.sleep(0.05)
        if not left:
            return


class Leftovers:
    """The threads and child processes alive before a plugin call, to end or report what it left."""

    def __init__(self) -> None:
        self.threads = set(threading.enumerate())
        self.children = child_pids()

    def clean_up(self, attacker: str, stage: str) -> None:
        """End the children the call left alive and remember its non-daemon threads (logged)."""
        children = child_pids() - self.children - live_pids()  # an isolated attacker's own process stays
        if children:
            log.warning("attacker %r left %d child process(es) running after %s (pid %s); ending them", attacker,
                        len(children), stage, ", ".join(map(str, sorted(children))))
            _end(children)
        threads = [t for t in threading.enumerate() if t not in self.threads and t.is_alive() and not t.daemon]
        if threads:
            log.warning("attacker %r left %d thread(s) running after %s (%s); the run will not wait for them",
                        attacker, len(threads), stage, ", ".join(t.name for t in threads))
            _STRAY.extend((attacker, t) for t in threads)


def attempt(attacker: str, stage: str, work: Callable[[], T], budget_s: float | None = None,
            cache_root: Path | None = None) -> T | RowError:
    """Run `work` within `budget_s` seconds (None: no limit); anything it raises, or running out of
    time, becomes the RowError of `attacker` at `stage` (and is logged). With `cache_root` (the run's
    attack folder), a call that changed another attacker's cached files fails too (``CacheGuard``).

    Anything means any BaseException but the user's own Ctrl-C (KeyboardInterrupt): a plugin's
    ``raise SystemExit(3)`` or ``sys.exit()`` would otherwise end the run with nothing written."""
    guard = None if cache_root is None else CacheGuard(cache_root, attacker)
    leftovers = Leftovers()
    try:
        with time_budget(budget_s, f"{attacker} ({stage})"):
            result = work()
    except KeyboardInterrupt:
        raise
    except BaseException as exc:  # noqa: BLE001 - a broken plugin must not take the run down
        log.warning("attacker %r failed at %s: %s: %s", attacker, stage, type(exc).__name__, exc)
        result = RowError(attacker, stage, shortened(f"{type(exc).__name__}: {exc}"))
    leftovers.clean_up(attacker, stage)
    tampered = None if guard is None else guard.failure(attacker, stage)
    return result if tampered is None else tampered


# A row's error says what failed in a sentence or two; a library's own dump (torch's dispatcher lists
# every backend, kilobytes of it) goes to the log whole.
MAX_ERROR_CHARS = 500


def shortened(message: str, limit: int = MAX_ERROR_CHARS) -> str:
    """`message` cut to `limit` characters, saying how much more the log holds."""
    if len(message) <= limit:
        return message
    return f"{message[:limit].rstrip()} ... ({len(message) - limit} more characters in the log)"


def describe(attacker: attacks.Attack) -> dict | RowError:
    """The attacker's `describe()` (its settings, stored with its rows), or the RowError of its
    raising or returning something other than a dict (stage "load": it cannot be set up)."""
    def checked() -> dict:
        described = attacker.describe()
        if not isinstance(described, dict):
            raise TypeError(f"returned {type(described).__name__}; expected a dict")
        return described
    result = attempt(attacker.name, "load", checked)
    if isinstance(result, RowError):
        return RowError(result.attacker, result.stage, f"{attacker.name}.describe() failed: {result.message}")
    return result
