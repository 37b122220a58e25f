"""The shared plate renderer: the scenes render through it, bit-identically to before it moved."""

from __future__ import annotations

import hashlib

import numpy as np

import common.plate_render as shared
import common.plate_render as scene_plates
from benchmark.scenes.synthetic import generate_synthetic

# sha256 of the outputs of common.plate_render on main before the renderer moved (2026-11-22,
# Pillow and FreeType of the suite's environment).
PLATES_SHA256 = "6d06d40cda77fb16277223ed8ffec4c89a8cb4e9d21fb935e348e2d5622d66bb"
SCENE_SHA256 = "cbd3a3a444cedfd23c53b40abbfe1c5a4dc74c5f524bcb300c877c46690a380b"


def test_scenes_use_the_shared_renderer():
    assert scene_plates.render_plate is shared.render_plate
    assert scene_plates.random_plate_text is shared.random_plate_text


def test_rendered_plates_and_scenes_are_bit_identical_to_before_the_move():
    h = hashlib.sha256()
    for text, size, background, band in [("AB123CD", (64, 14), (236, 236, 228), False),
                                         ("XY987ZW", (17, 4), (240, 210, 40), True),
                                         ("MM000II", (160, 34), (236, 236, 228), True)]:
        h.update(np.asarray(shared.render_plate(text, size, background, band)).tobytes())
    assert h.hexdigest() == PLATES_SHA256
    scene = generate_synthetic((128, 256), 3, "s")
    assert hashlib.sha256(scene.image.tobytes()).hexdigest() == SCENE_SHA256


def test_format_alphabets_follow_the_format():
    assert [len(a) for a in shared.format_alphabets("LLDDDLL")] == [26, 26, 10, 10, 10, 26, 26]
