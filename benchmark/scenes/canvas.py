"""Drawing surface of the synthetic scenes: RGB albedo, material and plate-instance maps.

Every shape is drawn with PIL (fast C polygon fill) into an RGB image and, with the same
geometry, into a material map. A material is a (train id, surface) pair: the train id gives the
label, the surface gives the texture that ``finish`` multiplies onto the flat albedo. Plates are
also drawn into an instance map, so their visible fraction after occlusion can be counted.
"""

from __future__ import annotations

from collections.abc import Sequence
from enum import IntEnum

import numpy as np
from PIL import Image, ImageDraw

from .labels import IGNORE_ID
from .textures import texture_crops

Point = tuple[float, float]
Colour = tuple[int, int, int]


class Surface(IntEnum):
    """Texture family of a material; amplitudes of (grain, cloud, leaf) noise are in ``_AMPLITUDES``."""

    SMOOTH = 0
    ASPHALT = 1
    CONCRETE = 2
    PLASTER = 3
    GLASS = 4
    PAINT = 5
    FOLIAGE = 6
    GRASS = 7
    SKY = 8
    RUBBER = 9
    FABRIC = 10


_AMPLITUDES = np.array(
    [
        (0.01, 0.01, 0.00),  # SMOOTH: plates, lamps, sign faces stay crisp
        (0.10, 0.05, 0.00),  # ASPHALT
        (0.07, 0.05, 0.00),  # CONCRETE
        (0.04, 0.06, 0.00),  # PLASTER
        (0.02, 0.15, 0.00),  # GLASS: reflections
        (0.02, 0.04, 0.00),  # PAINT
        (0.05, 0.12, 0.30),  # FOLIAGE
        (0.10, 0.10, 0.15),  # GRASS
        (0.00, 0.04, 0.00),  # SKY: soft clouds
        (0.08, 0.05, 0.00),  # RUBBER
        (0.06, 0.08, 0.00),  # FABRIC
    ],
    dtype=np.float32,
)

_STRIDE = 20  # material id = surface * _STRIDE + train id; 19 train ids fit below 20.


def material(train_id: int, surface: Surface) -> int:
    """Material id of a (train id, surface) pair, as stored in the material map."""
    return int(surface) * _STRIDE + train_id


def _luts() -> tuple[np.ndarray, np.ndarray]:
    ids = np.arange(256)
    labels = np.where(ids % _STRIDE < 19, ids % _STRIDE, IGNORE_ID).astype(np.uint8)
    surface = np.minimum(ids // _STRIDE, len(_AMPLITUDES) - 1)
    return labels, np.ascontiguousarray(_AMPLITUDES[surface].T)


_LABEL_LUT, _AMPLITUDE_LUT = _luts()


class Canvas:
    """An (H, W) scene being drawn; starts as a vertical sky gradient labelled sky."""

    def __init__(self, size: tuple[int, int], sky_top: Colour, sky_bottom: Colour, sky_id: int) -> None:
        height, width = size
        ramp = np.linspace(0.0, 1.0, height, dtype=np.float32)[:, None, None] ** 0.7
        sky = np.asarray(sky_top, np.float32) * (1 - ramp) + np.asarray(sky_bottom, np.float32) * ramp
        self.size = size
        # Stretching a one-pixel-wide column is much faster than materialising the gradient in numpy.
        self.rgb = Image.fromarray(sky.astype(np.uint8)).resize((width, height), Image.Resampling.NEAREST)
        self.materials = Image.new("L", (width, height), material(sky_id, Surface.SKY))
        self.plates = Image.new("L", (width, height), 0)
        self._draw_rgb = ImageDraw.Draw(self.rgb)
        self._draw_mat = ImageDraw.Draw(self.materials)
        self._draw_plate = ImageDraw.Draw(self.plates)
        # Once a plate is drawn, every later shape may occlude it and must clear the instance map.
        self._occluding = False

    def polygon(self, points: Sequence[Point], colour: Colour, train_id: int, surface: Surface) -> None:
        """Fill a polygon given in pixel coordinates."""
        self._draw_rgb.polygon(points, fill=colour)
        self._draw_mat.polygon(points, fill=material(train_id, surface))
        if self._occluding:
            self._draw_plate.polygon(points, fill=0)

    def ellipse(self, box: tuple[float, float, float, float], colour: Colour, train_id: int, surface: Surface) -> None:
        """Fill the ellipse inscribed in pixel box (x1, y1, x2, y2)."""
        if box[2] - box[0] < 1 or box[3] - box[1] < 1:
            return
        self._draw_rgb.ellipse(box, fill=colour)
        self._draw_mat.ellipse(box, fill=material(train_id, surface))
        if self._occluding:
            self._draw_plate.ellipse(box, fill=0)

    def ring(self, box: tuple[float, float, float, float], width_px: float, colour: Colour, train_id: int,
             surface: Surface) -> None:
        """Draw an ellipse outline of ``width_px`` (wheels), leaving the inside untouched."""
        if box[2] - box[0] < 1 or box[3] - box[1] < 1:
            return
        width = max(1, round(width_px))
        self._draw_rgb.ellipse(box, outline=colour, width=width)
        self._draw_mat.ellipse(box, outline=material(train_id, surface), width=width)
        if self._occluding:
            self._draw_plate.ellipse(box, outline=0, width=width)

    def line(self, points: Sequence[Point], width_px: float, colour: Colour, train_id: int, surface: Surface) -> None:
        """Draw a polyline ``width_px`` wide (at least one pixel)."""
        width = max(1, round(width_px))
        self._draw_rgb.line(points, fill=colour, width=width)
        self._draw_mat.line(points, fill=material(train_id, surface), width=width)
        if self._occluding:
            self._draw_plate.line(points, fill=0, width=width)

    def plate(self, image: Image.Image, top_left: tuple[int, int], plate_id: int, train_id: int) -> None:
        """Paste a rendered plate; ``plate_id`` (1..255) marks its pixels in the instance map."""
        x1, y1 = top_left
        box = (x1, y1, x1 + image.width - 1, y1 + image.height - 1)
        self.rgb.paste(image, top_left)
        self._draw_mat.rectangle(box, fill=material(train_id, Surface.SMOOTH))
        self._draw_plate.rectangle(box, fill=plate_id)
        self._occluding = True

    def finish(self, rng: np.random.Generator, exposure: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Texture and return (image (H,W,3) float32 in [0,1], labels (H,W) uint8, plate map (H,W) uint8)."""
        materials = np.asarray(self.materials)
        noise = texture_crops(self.size, rng)
        shading = np.full(self.size, exposure / 255.0, dtype=np.float32)
        for amplitude, field in zip(_AMPLITUDE_LUT, noise):
            shading += (amplitude * (exposure / 255.0))[materials] * field
        image = np.asarray(self.rgb, dtype=np.float32) * shading[..., None]
        np.clip(image, 0.0, 1.0, out=image)
        return image, _LABEL_LUT[materials], np.asarray(self.plates).copy()
