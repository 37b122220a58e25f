"""Attackers in processes of their own, for plugins not shipped with the suite (by default; ``--no-isolate``
keeps them in the runner's process, which a ``--sealed`` run refuses): the runner holds a stand-in
(``proxies``) whose methods are requests to the attacker's process (``process``, serving in ``worker``);
what crosses is what the threat model grants (``views``), and what comes back is parsed as data, never
unpickled (``wire``)."""

from benchmark.runner.sandbox.process import AttackerProcessError, PluginError, live_pids
from benchmark.runner.sandbox.proxies import ISOLATED, is_stand_in, isolated

__all__ = ["ISOLATED", "AttackerProcessError", "PluginError", "is_stand_in", "isolated", "live_pids"]
