"""Licence-plate format and rendering: a light plate, dark border, TrueType text.

Shared by the synthetic scenes (``common/plate_render.py`` re-exports it) and by attackers that
know the plate format and font (``ideal-observer``), which may not import ``benchmark``.
"""

from __future__ import annotations

import math
import string
from functools import lru_cache
from pathlib import Path

import matplotlib
import numpy as np
from PIL import Image, ImageDraw, ImageFont

PLATE_FORMAT: str = "LLDDDLL"
"""Plate text pattern: L = letter A-Z, D = digit 0-9 (an EU-style 7-character plate)."""

PLATE_SIZE_M: tuple[float, float] = (0.52, 0.11)
"""Physical plate (width, height) in metres (EU plate), used to size plates in the scene."""

_ALPHABETS: dict[str, str] = {"L": string.ascii_uppercase, "D": string.digits}

_FONT_PATH = Path(matplotlib.get_data_path()) / "fonts" / "ttf" / "DejaVuSans-Bold.ttf"

# Plates are drawn at this height and then downsampled, so that small plates are antialiased
# like a real camera would see them instead of being rasterised from an illegible tiny font.
_RENDER_HEIGHT_PX = 48


def plate_entropy_bits(fmt: str = PLATE_FORMAT) -> float:
    """log2 of the number of distinct plate strings of format ``fmt`` (L = 26 letters, D = 10 digits)."""
    _check_format(fmt)
    return sum(math.log2(len(_ALPHABETS[c])) for c in fmt)


def format_alphabets(fmt: str = PLATE_FORMAT) -> list[str]:
    """The alphabet of each position of format ``fmt`` (26 letters for 'L', 10 digits for 'D')."""
    _check_format(fmt)
    return [_ALPHABETS[c] for c in fmt]


def random_plate_text(rng: np.random.Generator, fmt: str = PLATE_FORMAT) -> str:
    """Draw a plate string of format ``fmt`` uniformly at random."""
    _check_format(fmt)
    return "".join(_ALPHABETS[c][rng.integers(len(_ALPHABETS[c]))] for c in fmt)


def matches_format(text: str, fmt: str = PLATE_FORMAT) -> bool:
    """Whether ``text`` is a string of format ``fmt``."""
    return len(text) == len(fmt) and all(ch in _ALPHABETS[c] for ch, c in zip(text, fmt))


def _check_format(fmt: str) -> None:
    bad = sorted(set(fmt) - set(_ALPHABETS))
    if bad or not fmt:
        raise ValueError(f"plate format {fmt!r}: use only 'L' (letter) and 'D' (digit), got {bad or 'empty'}")


@lru_cache(maxsize=64)
def plate_font(size_px: int) -> ImageFont.FreeTypeFont:
    """The plates' font (DejaVu Sans Bold) at `size_px` pixels."""
    return ImageFont.truetype(str(_FONT_PATH), size_px)


def render_plate(
    text: str,
    size_px: tuple[int, int],
    background: tuple[int, int, int] = (236, 236, 228),
    eu_band: bool = False,
) -> Image.Image:
    """Render a plate as an RGB PIL image of ``size_px = (width, height)`` pixels.

    A light ``background`` with a dark border and black text in DejaVu Sans Bold
    (proportional, unslashed zero, like the plate fonts of most countries);
    ``eu_band`` adds the blue strip on the left of EU plates.
    """
    width, height = size_px
    render_h = max(_RENDER_HEIGHT_PX, height)
    render_w = max(round(render_h * width / height), 8)
    plate = Image.new("RGB", (render_w, render_h), background)
    draw = ImageDraw.Draw(plate)
    border = max(1, render_h // 16)
    draw.rectangle((0, 0, render_w - 1, render_h - 1), outline=(20, 20, 20), width=border)
    left = border
    if eu_band:
        band_w = render_w // 12
        draw.rectangle((border, border, border + band_w, render_h - 1 - border), fill=(0, 51, 153))
        left += band_w
    font = plate_font(round(render_h * 0.78))
    x1, y1, x2, y2 = draw.textbbox((0, 0), text, font=font)
    scale = min(1.0, (render_w - left - 3 * border) / (x2 - x1))
    if scale < 1.0:
        font = plate_font(max(1, int(round(render_h * 0.78 * scale))))
        x1, y1, x2, y2 = draw.textbbox((0, 0), text, font=font)
    cx = (left + render_w - border) / 2
    draw.text((cx - (x1 + x2) / 2, render_h / 2 - (y1 + y2) / 2), text, fill=(15, 15, 15), font=font)
    if (render_w, render_h) == (width, height):
        return plate
    return plate.resize((width, height), Image.Resampling.BOX)
