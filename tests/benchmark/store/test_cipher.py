"""A sealed run's cache files are unreadable without the run's key, and read back exactly with it."""

import os

import pytest

from benchmark.store.cipher import MAGIC, CipherError, decrypt, encrypt, run_key


def test_round_trip_is_exact_and_the_ciphertext_hides_the_text():
    key = run_key({0: 2**61 + 7})
    data = b'{"truth": "NP160FJ"}' * 50 + os.urandom(1000)
    blob = encrypt(key, "result.json", data)
    assert blob.startswith(MAGIC) and b"NP160FJ" not in blob
    assert decrypt(key, "result.json", blob) == data
    assert encrypt(key, "result.json", data) != blob  # a fresh nonce each time


def test_another_key_or_file_name_gives_no_plaintext():
    data = b"NP160FJ " * 20
    blob = encrypt(run_key({0: 1}), "a.png", data)
    assert decrypt(run_key({0: 2}), "a.png", blob) != data
    assert decrypt(run_key({0: 1}), "b.png", blob) != data


def test_the_key_is_a_function_of_the_scene_seeds_and_none_without():
    assert run_key({}) is None
    assert run_key({0: 5, 1: 6}) == run_key({1: 6, 0: 5}) != run_key({0: 5, 1: 7})


def test_bytes_that_were_not_encrypted_are_refused():
    with pytest.raises(CipherError, match="not an encrypted file"):
        decrypt(run_key({0: 1}), "x", b"\x89PNG\r\n")
