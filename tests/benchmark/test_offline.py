"""A smoke run makes no outbound name lookup or connection, from Python or from a native thread
(ONNX Runtime's telemetry looked up ``mobile.events.data.microsoft.com`` 6-12 times a run from its
own threads until ``attacks`` set ``ORT_DISABLE_TELEMETRY``).

Two nets catch it: a ``sitecustomize`` that refuses and records every Python-level lookup or
connection, and ``strace -f -e trace=network`` that records every socket the process or any of
its threads opens (the native threads that Python's patches cannot see). The run is small: one
lens, the identity restorer and the lpdr reader (its OCR runs through ONNX Runtime, as does the
utility net's SegFormer), on the smoke profile with a fresh cache so that every network runs.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow  # a smoke run in a subprocess under strace

ROOT = Path(__file__).resolve().parents[2]

SITECUSTOMIZE = '''
import os, socket
_LOG = os.environ["PLB_NETWORK_LOG"]

def _refuse(what):
    def refused(*args, **kwargs):
        with open(_LOG, "a") as f:
            f.write(f"{what} {args[:2]!r}\\n")
        raise OSError(f"network access attempted during an offline run: {what}")
    return refused

for _name in ("getaddrinfo", "gethostbyname", "gethostbyname_ex", "gethostbyaddr", "create_connection"):
    setattr(socket, _name, _refuse(_name))
socket.socket.connect = _refuse("connect")
socket.socket.connect_ex = _refuse("connect_ex")
socket.socket.sendto = _refuse("sendto")
'''

# Internet sockets (a DNS query is a UDP socket to port 53; curl first probes IPv6 with one) and
# any address of those families handed to connect/sendto/sendmsg/bind. Local (AF_UNIX) sockets,
# e.g. glibc asking nscd for a user name, are not network.
_NETWORK = re.compile(r"socket\(AF_INET6?\b|sa_family=AF_INET6?\b")


def _strace_works() -> str | None:
    """Why strace cannot trace a child here, or None when it can."""
    if shutil.which("strace") is None:
        return "strace is not installed (apt-get install strace; .ci/run installs it)"
    probe = subprocess.run(["strace", "-f", "-qq", "-e", "trace=network", "-o", os.devnull, "true"],
                           capture_output=True, text=True)
    if probe.returncode != 0:
        return f"strace cannot trace here (ptrace not permitted?): {probe.stderr.strip()[:200]}"
    return None


def test_a_smoke_run_reaches_no_network(tmp_path):
    why = _strace_works()
    if why:
        pytest.skip(why)
    site = tmp_path / "site"
    site.mkdir()
    (site / "sitecustomize.py").write_text(SITECUSTOMIZE)
    home = tmp_path / "home"
    home.mkdir()
    python_log, trace = tmp_path / "python_network.log", tmp_path / "strace.log"
    env = {k: v for k, v in os.environ.items() if k != "ORT_DISABLE_TELEMETRY"}  # the package must set it
    env.update(PYTHONPATH=os.pathsep.join([str(site), str(ROOT)]), PLB_NETWORK_LOG=str(python_log),
               PLB_CACHE=str(tmp_path / "cache"), HOME=str(home))
    out = tmp_path / "out"
    command = [sys.executable, "-m", "benchmark", "-q", "run", "--lens", "ideal", "--attack", "identity",
               "--attack", "lpdr", "--profile", "smoke", "--out", str(out)]
    done = subprocess.run(["strace", "-f", "-qq", "-e", "trace=network", "-o", str(trace), *command],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]

    # The run did its work, ONNX Runtime included: rows of the reader and the utility net are ok.
    rows = json.loads((out / "results.json").read_text())["rows"]
    ok = {(r["kind"], r["attack"]) for r in rows if r["status"] == "ok"}
    assert ("reader", "lpdr") in ok and ("utility", "utility") in ok, sorted(ok)

    assert not python_log.exists(), f"Python-level network calls:\n{python_log.read_text()}"
    reached = [line for line in trace.read_text().splitlines() if _NETWORK.search(line)]
    assert not reached, "network syscalls during an offline smoke run:\n" + "\n".join(reached[:20])
    # Nor does ONNX Runtime's telemetry leave its device id and event store behind.
    assert not (home / ".cache" / "Microsoft").exists()
