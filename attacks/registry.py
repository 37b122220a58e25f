"""Plugin discovery through entry points, generic over the group.

Built-in and third-party plugins register the same way: an entry point in a group such as
``privacy_lens_bench.attacks`` or ``privacy_lens_bench.lenses`` (ours are declared in this
project's ``pyproject.toml``). Discovery itself (``discover``, ``suggest``) is shared with the
lens registry and lives in ``common.plugins``; this module is the attacker registry built on it
(``attacks.load``, ``attacks.available``, ``attacks.load_all``) and ``import_from_file``.
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib.util
import logging
import re
import sys
from collections.abc import Callable
from importlib.metadata import EntryPoint
from pathlib import Path

from attacks.base import Attack, Reader, Restorer, ThreatModel
from common.plugins import DuplicateNameError, discover, similar, source_of, suggest

__all__ = [
    "ATTACKS_GROUP",
    "DuplicatePluginError",
    "PluginFailure",
    "UnknownAttackError",
    "UnknownPluginError",
    "available",
    "discover",
    "import_from_file",
    "load",
    "load_all",
    "outside_suite",
    "similar",
    "source_of",
    "suggest",
]

ATTACKS_GROUP = "privacy_lens_bench.attacks"

logger = logging.getLogger(__name__)


DuplicatePluginError = DuplicateNameError  # one error for every plugin group


class UnknownPluginError(LookupError, ValueError):
    """A name is not registered in a group (or a file/attribute spec does not resolve)."""


def import_from_file(spec: str) -> object:
    """Import ``'path/to/file.py:Attr'`` and return ``Attr``.

    The module is registered in ``sys.modules`` under a name derived from its absolute path, so
    importing the same file twice gives the same objects (and pickling of its classes works).

    Raises:
        UnknownPluginError: The spec has no ``:Attr``, the file does not exist, or it lacks
            ``Attr``. Errors raised while executing the module propagate unchanged.
    """
    path_part, sep, attr = spec.rpartition(":")
    if not sep or not path_part or not attr:
        raise UnknownPluginError(f"{spec!r}: expected 'path/to/file.py:Name'")
    path = Path(path_part).expanduser().resolve()
    if not path.is_file():
        raise UnknownPluginError(f"{spec!r}: file {str(path)!r} does not exist")
    module_name = f"_plb_plugin_{path.stem}_{hashlib.sha1(str(path).encode()).hexdigest()[:12]}"
    module = sys.modules.get(module_name)
    if module is None:
        module_spec = importlib.util.spec_from_file_location(module_name, path)
        if module_spec is None or module_spec.loader is None:
            raise UnknownPluginError(f"{spec!r}: {str(path)!r} is not an importable Python file")
        module = importlib.util.module_from_spec(module_spec)
        sys.modules[module_name] = module
        try:
            module_spec.loader.exec_module(module)
        except BaseException:
            del sys.modules[module_name]
            raise
    try:
        return getattr(module, attr)
    except AttributeError:
        public = sorted(n for n in vars(module) if not n.startswith("_"))
        raise UnknownPluginError(
            f"{spec!r}: {str(path)!r} defines no {attr!r}; it defines {public}"
        ) from None


class UnknownAttackError(UnknownPluginError):
    """``attacks.load`` was given a name that no installed distribution registers."""


@dataclasses.dataclass(frozen=True)
class PluginFailure:
    """An attacker that could not be loaded and was skipped.

    Attributes:
        name: The registered name or file spec that failed.
        error: ``'<ExceptionType>: <message>'`` of what went wrong.
        kind: "restorer" or "reader" when the class was found but failed to construct, else None.
    """

    name: str
    error: str
    kind: str | None = None


def available() -> dict[str, str]:
    """Registered attackers as ``{name: 'module:attr'}``, without importing any of them.

    Raises:
        DuplicatePluginError: Two distributions register the same name.
    """
    return {name: ep.value for name, ep in sorted(discover(ATTACKS_GROUP).items())}


def load(spec: str, **options: object) -> Attack:
    """Create an attacker from a registered name or a ``'path/to/file.py:ClassName'`` spec.

    Args:
        spec: A name from ``available()`` or a file spec (``'<path>.py:<attribute>'``).
        **options: Keyword arguments for the attacker's constructor.

    Raises:
        UnknownAttackError: Unknown name (the message lists registered names and close
            matches), or a file spec whose file or class does not exist.
        DuplicatePluginError: Two distributions register the same name.
        TypeError: The object is not an ``Attack`` subclass, or its ``name`` differs from
            the name it is registered under.
    """
    return _load(spec, discover(ATTACKS_GROUP), options)


def load_all(names: list[str] | None = None, load_outside: Callable[[str], Attack] | None = None
             ) -> tuple[list[Attack], list[PluginFailure]]:
    """Load several attackers one at a time; those that fail are skipped, not fatal.

    Args:
        names: Names or file specs to load, in order; None loads every registered attacker
            in name order.
        load_outside: Loads a file spec or an entry point of another distribution than this suite's
            (``outside_suite``) instead of importing it here: the runner's stand-in for an attacker in a
            process of its own. None: every attacker is imported here.

    Returns:
        The attackers that loaded, and one ``PluginFailure`` per attacker that raised while
        importing or constructing (each also logged as a warning naming it).

    Raises:
        UnknownAttackError: A requested name is not registered, or a requested file spec does
            not resolve: a typo by the caller, not a broken plugin.
        DuplicatePluginError: Two distributions register the same name.
    """
    registered = discover(ATTACKS_GROUP)
    requested = sorted(registered) if names is None else list(dict.fromkeys(names))
    for name in requested:
        if not _is_file_spec(name) and name not in registered:
            raise _unknown(name, registered)
    loaded: list[Attack] = []
    failures: list[PluginFailure] = []
    sources: dict[str, str] = {}  # attacker name -> where it came from
    for spec in requested:
        kind = None
        try:
            if load_outside is not None and outside_suite(spec, registered):
                attacker = load_outside(spec)
                if spec in registered and attacker.name != spec:
                    raise TypeError(f"{_origin(spec, registered)}: registered as {spec!r} but its class attribute "
                                    f"name is {attacker.name!r}; they must match (results are keyed by it)")
            else:
                obj, origin, registered_name = _import(spec, registered)
                if isinstance(obj, type):
                    kind = "reader" if issubclass(obj, Reader) else "restorer" if issubclass(obj, Restorer) else None
                attacker = _checked_class(obj, origin, registered_name)()
        except (UnknownPluginError, KeyboardInterrupt):  # a typo by the caller; the user's own Ctrl-C
            raise
        except BaseException as exc:  # noqa: BLE001 - any plugin bug, a SystemExit too, must not take the run down
            failure = PluginFailure(spec, f"{type(exc).__name__}: {exc}", kind)
            logger.warning("attacker %r failed to load and is skipped: %s", spec, failure.error)
            failures.append(failure)
            continue
        _check_unique(attacker.name, _origin(spec, registered), sources, registered)
        loaded.append(attacker)
    return loaded, failures


SUITE_DISTRIBUTION = "privacy-lens-bench"


def outside_suite(spec: str, registered: dict[str, EntryPoint]) -> bool:
    """Whether `spec` names a plugin not shipped with this suite: a file spec, or an entry point of
    another distribution (an unknown name is not: it is an error)."""
    if _is_file_spec(spec):
        return True
    ep = registered.get(spec)
    if ep is None:
        return False
    dist = getattr(ep, "dist", None)
    return dist is None or re.sub(r"[-_.]+", "-", dist.name).lower() != SUITE_DISTRIBUTION


def _origin(spec: str, registered: dict[str, EntryPoint]) -> str:
    return f"file {spec}" if _is_file_spec(spec) else f"entry point {source_of(registered[spec])}"


def _check_unique(name: str, origin: str, sources: dict[str, str], registered: dict[str, EntryPoint]) -> None:
    """Raise DuplicatePluginError when `name` is taken by another selected attacker or, for a file
    plugin, by a registered one (results are keyed by name: two would overwrite each other)."""
    other = sources.get(name)
    if other is None and name in registered and origin.startswith("file "):
        other = f"entry point {source_of(registered[name])}"
    if other is not None:
        raise DuplicatePluginError(f"attacker name {name!r} is defined twice: by {other} and by {origin}; "
                                   "rename one of them (results are keyed by the name)")
    sources[name] = origin


def _load(spec: str, registered: dict[str, EntryPoint], options: dict[str, object]) -> Attack:
    return _checked_class(*_import(spec, registered))(**options)


def _import(spec: str, registered: dict[str, EntryPoint]) -> tuple[object, str, str | None]:
    """The object a registered name or file spec points at, where it came from, and its registered name."""
    if _is_file_spec(spec):
        return import_from_file(spec), spec, None
    if spec in registered:
        ep = registered[spec]
        return ep.load(), source_of(ep), spec
    raise _unknown(spec, registered)


def _checked_class(obj: object, origin: str, registered_name: str | None) -> type[Attack]:
    """`obj` if it is an Attack subclass with a `name` (matching its registration) and a `threat_model`."""
    if not (isinstance(obj, type) and issubclass(obj, Attack)):
        raise TypeError(f"{origin}: {obj!r} is not a subclass of attacks.Attack")
    name = getattr(obj, "name", None)
    if not isinstance(name, str) or not name:
        raise TypeError(f"{origin}: class {obj.__name__} needs a class attribute `name` (a non-empty str, the "
                        f"attacker's name in results), got {name!r}")
    if not isinstance(getattr(obj, "threat_model", None), ThreatModel):
        raise TypeError(f"{origin}: class {obj.__name__} needs a class attribute `threat_model` "
                        f"(an attacks.ThreatModel: {[t.value for t in ThreatModel]})")
    if registered_name is not None and name != registered_name:
        raise TypeError(
            f"{origin}: registered as {registered_name!r} but its class attribute "
            f"name is {name!r}; they must match (results are keyed by it)"
        )
    return obj


def _is_file_spec(spec: str) -> bool:
    return ".py:" in spec


def _unknown(name: str, registered: dict[str, EntryPoint]) -> UnknownAttackError:
    return UnknownAttackError(
        f"unknown attacker {name!r}.{suggest(name, registered)} Registered ({ATTACKS_GROUP}): "
        f"{sorted(registered)}; or pass 'path/to/file.py:ClassName'."
    )
