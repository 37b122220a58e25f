"""Attackers handed to `benchmark.run` as Python objects (a class or an instance), not as names.

Tasks load their attackers from a spec string (`planning.AttackerRef.spec`), so an object must
be turned into one that the process running the task can resolve:

- Local executor: the object is registered in this process under `in-process:NAME@KEY`; a class
  is constructed afresh for each task (like a registered name), an instance is deep-copied for
  each task so tasks never share fitted state. Such a spec means nothing in another process.
- Ray executor: only a class defined at the top level of an importable module can travel, as
  `module:QualName`, and every worker must be able to import that module (installed, or on the
  workers' PYTHONPATH). An instance cannot travel (its options are not a recipe to rebuild it:
  `describe()` reports settings, it does not reconstruct), nor can a class defined in `__main__`
  (a script or notebook) or inside a function; both raise `AttackerTransportError`.

`KEY` hashes the attacker's `describe()` and its class's source text, and keys the run's cache
(`AttackerRef.settings_key`), so two instances with different options, or an edited class, do
not reuse each other's task results. A class whose source cannot be read (defined in a REPL) is
keyed by `describe()` alone: edit it and re-run, and stale results may be found.
"""

from __future__ import annotations

import copy
import importlib
import inspect
from collections.abc import Callable

import attacks
from benchmark.store.cache import config_hash
from benchmark.runner.planning import AttackerRef
from benchmark.runner.sandbox import ISOLATED, isolated

IN_PROCESS = "in-process:"

# Factories of the attackers registered in this process, by spec.
_REGISTERED: dict[str, Callable[[], attacks.Attack]] = {}


class AttackerTransportError(ValueError):
    """An attacker object cannot reach the processes that run the tasks (e.g. an instance on Ray)."""


def is_attacker_object(item: object) -> bool:
    """Whether `item` is an attacker class or instance (rather than a name or a file spec)."""
    return isinstance(item, attacks.Attack) or (isinstance(item, type) and issubclass(item, attacks.Attack))


def check_class(cls: type) -> None:
    """Raise TypeError naming `cls` unless it is a concrete Restorer or Reader with a name and a threat model."""
    if not (isinstance(cls, type) and issubclass(cls, (attacks.Restorer, attacks.Reader))):
        raise TypeError(f"attacker {cls!r} must subclass attacks.Restorer or attacks.Reader")
    name = getattr(cls, "name", None)
    if not isinstance(name, str) or not name:
        raise TypeError(f"attacker class {cls.__qualname__} needs a class attribute `name` (a non-empty str, its "
                        f"name in results), got {name!r}")
    if not isinstance(getattr(cls, "threat_model", None), attacks.ThreatModel):
        raise TypeError(f"attacker class {cls.__qualname__} needs a class attribute `threat_model` "
                        f"(an attacks.ThreatModel: {[t.value for t in attacks.ThreatModel]})")
    if inspect.isabstract(cls):
        raise TypeError(f"attacker class {cls.__qualname__} leaves {sorted(cls.__abstractmethods__)} abstract")


def settings_key(attacker: attacks.Attack) -> str:
    """Hash of the attacker's `describe()` and its class's source ('' source when unreadable)."""
    try:
        source = inspect.getsource(type(attacker))
    except (OSError, TypeError):
        source = ""
    return config_hash({"describe": attacker.describe(), "source": source})


def module_spec(cls: type) -> str:
    """`module:QualName` of a class that another process can import, else AttackerTransportError."""
    where = f"attacker class {cls.__qualname__} (module {cls.__module__!r})"
    if cls.__module__ == "__main__":
        raise AttackerTransportError(f"{where} is defined in __main__ (a script or notebook), which Ray workers "
                                     "cannot import; move it into an importable module, or use executor='local'")
    if "<locals>" in cls.__qualname__:
        raise AttackerTransportError(f"{where} is defined inside a function; define it at the top level of an "
                                     "importable module, or use executor='local'")
    spec = f"{cls.__module__}:{cls.__qualname__}"
    try:
        found = resolve_module_spec(spec)
    except (ImportError, AttributeError) as exc:
        raise AttackerTransportError(f"{where} cannot be imported back as {spec!r} ({exc}); "
                                     "use executor='local'") from None
    if found is not cls:
        raise AttackerTransportError(f"{where}: importing {spec!r} gives another object; use executor='local'")
    return spec


def resolve_module_spec(spec: str) -> object:
    """The object named by `module:QualName` (importing the module)."""
    module_name, _, qualname = spec.partition(":")
    obj: object = importlib.import_module(module_name)
    for part in qualname.split("."):
        obj = getattr(obj, part)
    return obj


def check(item: type | attacks.Attack, remote: bool) -> None:
    """Raise unless `item` is an attacker class or instance that can reach the tasks.

    Args:
        item: An attacks.Restorer / attacks.Reader subclass or instance.
        remote: True when tasks run in other processes (Ray): the class must be importable there.

    Raises:
        TypeError: `item` is not a usable attacker class or instance.
        AttackerTransportError: `remote` and `item` cannot travel (see the module docstring).
    """
    cls = item if isinstance(item, type) else type(item)
    check_class(cls)
    if remote and not isinstance(item, type):
        raise AttackerTransportError(
            f"attacker instance {item.name!r} ({cls.__qualname__}) exists only in this process; a Ray worker "
            "cannot rebuild it from describe(). Pass its class (defined in an importable module, options as "
            "constructor defaults or a subclass), a registered name or 'path/file.py:Class', or use executor='local'")
    if remote:
        module_spec(cls)
    if not remote and not isinstance(item, type):
        try:
            copy.deepcopy(item)  # each task gets its own copy: fail here, naming it, not inside a task
        except Exception as exc:  # noqa: BLE001 - whatever deepcopy raises, the cause is the instance
            raise TypeError(f"attacker instance {item.name!r} cannot be copied for each task "
                            f"({type(exc).__name__}: {exc}); pass its class instead") from None


def reference(item: type | attacks.Attack, remote: bool) -> tuple[AttackerRef, attacks.Attack]:
    """The task-side reference of an attacker class or instance (`check`ed), and an instance of it.

    A class is constructed here once (for its name and `describe()`); whatever its constructor
    raises propagates, and the caller reports it as the attacker's load failure.
    """
    check(item, remote)
    attacker = item() if isinstance(item, type) else item
    key = settings_key(attacker)
    if remote:
        return AttackerRef(attacker.name, module_spec(type(attacker)), key), attacker
    spec = f"{IN_PROCESS}{attacker.name}@{key}"
    _REGISTERED[spec] = item if isinstance(item, type) else (lambda: copy.deepcopy(item))
    return AttackerRef(attacker.name, spec, key), attacker


def load(spec: str) -> attacks.Attack:
    """The attacker of a task's spec: isolated (``sandbox.ISOLATED`` + a name or file spec: a stand-in for
    the attacker in its own process), in-process object, `module:QualName`, file spec or registered name."""
    if spec.startswith(ISOLATED):
        return isolated(spec[len(ISOLATED):])
    if spec.startswith(IN_PROCESS):
        try:
            return _REGISTERED[spec]()
        except KeyError:
            raise AttackerTransportError(
                f"attacker {spec!r} was registered in the process that called benchmark.run, not in this one; "
                "in-process attackers run only with executor='local'") from None
    if ":" in spec and ".py:" not in spec:
        cls = resolve_module_spec(spec)
        check_class(cls)  # type: ignore[arg-type]
        return cls()  # type: ignore[operator]
    return attacks.load(spec)
