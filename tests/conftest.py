import os
import tempfile

# Tests never touch the user's cache, and never reach the network.
os.environ.setdefault("PLB_CACHE", tempfile.mkdtemp(prefix="plb-test-cache-"))
for var in ("HF_HUB_OFFLINE", "TRANSFORMERS_OFFLINE", "HF_DATASETS_OFFLINE"):
    os.environ[var] = "1"
