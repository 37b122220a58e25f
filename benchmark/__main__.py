import logging
import os
import sys

from benchmark.cli import main

code = main()
isolation = sys.modules.get("benchmark.runner.isolation")  # imported only by commands that run plugins
if isolation is not None and isolation.stray_threads():
    # A plugin left non-daemon threads running: the results are written, so end without waiting for them.
    names = ", ".join(f"{a}: {t.name}" for a, t in isolation.stray_threads())
    logging.getLogger("benchmark").warning("ending the process without waiting for the plugin thread(s) %s", names)
    sys.stdout.flush()
    sys.stderr.flush()
    logging.shutdown()
    os._exit(code)
sys.exit(code)
