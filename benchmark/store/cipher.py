"""Cache files a sealed run keeps from its attackers: a task's result (the scored plates' texts) and its
pictures (the sharp scenes, plate crops) are stored encrypted under a key made from the run's scene seeds,
which no attacker is given; the runner decrypts them when it reuses a task or writes the run's outputs.

An attacker runs as the user who runs the suite, so it can read the cache folder; without the key, what
it finds there tells it nothing about the test scenes. The cipher is a stream cipher from the standard
library: a SHAKE-256 keystream of (key, a random 16-byte nonce, the file's label) XORed with the data.
Integrity stays with the cache's SHA-256 sidecars (``cache.write_verified``), computed on the ciphertext.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Mapping

MAGIC = b"PLBSEAL1"
_NONCE_BYTES = 16


class CipherError(ValueError):
    """Bytes that are not a file encrypted under this key and label."""


def run_key(scene_seeds: Mapping[int, int]) -> bytes | None:
    """The key of a sealed run (its scene seeds: secret until the attackers ran); None for a run without."""
    if not scene_seeds:
        return None
    text = json.dumps({str(k): int(v) for k, v in sorted(scene_seeds.items())}, sort_keys=True)
    return hashlib.sha256(b"privacy-lens-bench sealed run\0" + text.encode()).digest()


def _xor(data: bytes, key: bytes, nonce: bytes, label: str) -> bytes:
    stream = hashlib.shake_256(key + nonce + label.encode()).digest(len(data))
    return (int.from_bytes(data, "little") ^ int.from_bytes(stream, "little")).to_bytes(len(data), "little")


def encrypt(key: bytes, label: str, data: bytes) -> bytes:
    """`data` encrypted for the file named `label`: MAGIC, a fresh nonce, then the ciphertext."""
    nonce = os.urandom(_NONCE_BYTES)
    return MAGIC + nonce + _xor(data, key, nonce, label)


def decrypt(key: bytes, label: str, blob: bytes) -> bytes:
    """The data of `encrypt(key, label, data)`; CipherError for bytes that were not encrypted so."""
    if not blob.startswith(MAGIC) or len(blob) < len(MAGIC) + _NONCE_BYTES:
        raise CipherError(f"{label}: not an encrypted file of a sealed run")
    nonce = blob[len(MAGIC):len(MAGIC) + _NONCE_BYTES]
    return _xor(blob[len(MAGIC) + _NONCE_BYTES:], key, nonce, label)


def plain(key: bytes | None, label: str, data: bytes) -> bytes:
    """A stored file's bytes as written: decrypted when a sealed run encrypted them (CipherError without
    its key), as they are otherwise."""
    if not data.startswith(MAGIC):
        return data
    if key is None:
        raise CipherError(f"{label} is encrypted (a sealed run's) and no key was given")
    return decrypt(key, label, data)
