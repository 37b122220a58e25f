import os
import shutil
import tempfile

# Tests never touch the user's cache, and never reach the network. A cache this session made is
# removed when it ends (each session used to leave one behind in /tmp); one passed in is kept.
_OWN_CACHE = None if "PLB_CACHE" in os.environ else tempfile.mkdtemp(prefix="plb-test-cache-")
if _OWN_CACHE is not None:
    os.environ["PLB_CACHE"] = _OWN_CACHE
for var in ("HF_HUB_OFFLINE", "TRANSFORMERS_OFFLINE", "HF_DATASETS_OFFLINE", "ORT_DISABLE_TELEMETRY"):
    os.environ[var] = "1"


def pytest_sessionfinish(session, exitstatus):
    if _OWN_CACHE is not None:
        shutil.rmtree(_OWN_CACHE, ignore_errors=True)
