"""Licence-plate text and rendering for the scenes: the shared renderer of ``attacks.plates.plate_render``."""

from attacks.plates.plate_render import (PLATE_FORMAT, PLATE_SIZE_M, format_alphabets, matches_format,
                                         plate_entropy_bits, random_plate_text, render_plate)

__all__ = ["PLATE_FORMAT", "PLATE_SIZE_M", "format_alphabets", "matches_format", "plate_entropy_bits",
           "random_plate_text", "render_plate"]
