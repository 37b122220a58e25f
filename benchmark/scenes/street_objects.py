"""Drawers for the objects of a synthetic street: vehicles, people, cyclists, poles, signs, trees.

Each drawer paints one object at world position (x, z) in metres onto a ``Canvas`` through a
``Camera`` and returns pixel points spanning what it covered (for the object's bounding box).
Shapes are given in the object's own frame: (dx, y) metres from its foot point. Colours go
through ``Tint`` so that far objects fade into the haze as in a real photograph.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .camera import Camera, Point
from .canvas import Canvas, Colour, Surface
from .labels import TRAIN_ID

Local = list[tuple[float, float]]
ToPixels = Callable[[Local], list[Point]]


@dataclass(frozen=True)
class Tint:
    """Aerial perspective: colours blend towards ``haze`` with depth (``visibility_m`` e-folding)."""

    haze: Colour
    visibility_m: float

    def __call__(self, colour: Colour, z_m: float, light: float = 1.0) -> Colour:
        a = 1.0 - math.exp(-z_m / self.visibility_m)
        r, g, b = (int(min(255.0, c * light * (1 - a) + h * a)) for c, h in zip(colour, self.haze))
        return r, g, b


@dataclass(frozen=True)
class VehicleKind:
    """Size in metres of a vehicle type, the height of its plate centre, and its nearest placement."""

    name: str
    width_m: float
    height_m: float
    length_m: float
    plate_y_m: float
    min_depth_m: float


# Minimum depths keep big vehicles from filling the whole frame.
CAR = VehicleKind("car", 1.8, 1.5, 4.4, 0.5, 3.6)
TRUCK = VehicleKind("truck", 2.5, 3.4, 8.0, 0.55, 9.0)
BUS = VehicleKind("bus", 2.55, 3.1, 12.0, 0.5, 9.0)
TRAM = VehicleKind("train", 2.65, 3.6, 25.0, 0.0, 14.0)

_GLASS: Colour = (45, 55, 65)
_TYRE: Colour = (22, 22, 24)
_DARK: Colour = (40, 40, 42)
_SKINS: tuple[Colour, ...] = ((240, 200, 170), (200, 150, 110), (140, 95, 65), (95, 65, 45))
_CLOTHES: tuple[Colour, ...] = ((30, 30, 35), (60, 70, 110), (150, 30, 40), (200, 200, 195), (90, 80, 60),
                                (40, 90, 60), (180, 140, 60), (110, 110, 115), (20, 40, 80))


def _rect(x1: float, y1: float, x2: float, y2: float) -> Local:
    return [(x1, y1), (x2, y1), (x2, y2), (x1, y2)]


def _ellipse(to_px: ToPixels, cx: float, cy: float, rx: float, ry: float) -> tuple[float, float, float, float]:
    (u1, v1), (u2, v2) = to_px([(cx - rx, cy + ry), (cx + rx, cy - ry)])
    return min(u1, u2), v1, max(u1, u2), v2


def draw_vehicle_shadow(canvas: Canvas, cam: Camera, tint: Tint, kind: VehicleKind, x: float, z: float) -> None:
    """Darken the road under a vehicle; drawn before all objects, since whatever stands on it hides it."""
    w = kind.width_m
    canvas.polygon(cam.ground(x - w / 2 - 0.1, x + w / 2 + 0.1, z + 0.1, z + kind.length_m), tint((30, 30, 32), z),
                   TRAIN_ID["road"], Surface.ASPHALT)


def draw_vehicle(canvas: Canvas, cam: Camera, tint: Tint, kind: VehicleKind, x: float, z: float,
                 colour: Colour, oncoming: bool) -> list[Point]:
    """Draw a vehicle whose rear (front if ``oncoming``) is at depth ``z``; the body extends to z + length."""
    tid, w, h = TRAIN_ID[kind.name], kind.width_m, kind.height_m
    covered: list[Point] = []
    # The side facing the optical axis shows behind the end face.
    if x - w / 2 > 0.2 or x + w / 2 < -0.2:
        covered += _vehicle_side(canvas, cam, tint, kind, x - w / 2 if x > 0 else x + w / 2, z, colour)

    def to_px(points: Local) -> list[Point]:
        return cam.front(x, z, points)

    def paint(points: Local, fill: Colour, surface: Surface, light: float = 1.0) -> None:
        canvas.polygon(to_px(points), tint(fill, z, light), tid, surface)

    covered += to_px([(-w / 2, 0.0), (w / 2, h)])
    for sx in (-1, 1):
        paint(_rect(sx * (w / 2 - 0.2) - 0.16, 0.0, sx * (w / 2 - 0.2) + 0.16, 0.4), _TYRE, Surface.RUBBER)
    if kind is CAR:
        paint(_rect(-w / 2, 0.28, w / 2, 0.95), colour, Surface.PAINT)
        paint([(-w / 2 + 0.08, 0.95), (w / 2 - 0.08, 0.95), (w / 2 - 0.28, h), (-w / 2 + 0.28, h)], colour,
              Surface.PAINT, 0.9)
        paint([(-w / 2 + 0.18, 1.0), (w / 2 - 0.18, 1.0), (w / 2 - 0.33, h - 0.07), (-w / 2 + 0.33, h - 0.07)],
              _GLASS, Surface.GLASS)
        paint(_rect(-w / 2, 0.28, w / 2, 0.4), _DARK, Surface.RUBBER)
        lamp_y = (0.72, 0.88)
    elif kind is TRUCK and oncoming:
        paint(_rect(-w / 2, 2.8, w / 2, h), (210, 210, 205), Surface.PAINT)
        paint([(-w / 2, 0.4), (w / 2, 0.4), (w / 2 - 0.05, 2.85), (-w / 2 + 0.05, 2.85)], colour, Surface.PAINT)
        paint([(-w / 2 + 0.12, 1.65), (w / 2 - 0.12, 1.65), (w / 2 - 0.15, 2.6), (-w / 2 + 0.15, 2.6)], _GLASS,
              Surface.GLASS)
        paint(_rect(-0.6, 0.75, 0.6, 1.4), _DARK, Surface.RUBBER)
        lamp_y = (0.75, 0.9)
    elif kind is TRUCK:
        paint(_rect(-w / 2 + 0.15, 0.35, w / 2 - 0.15, 0.95), _DARK, Surface.RUBBER)
        paint(_rect(-w / 2, 0.95, w / 2, h), colour, Surface.PAINT)
        canvas.line(to_px([(0.0, 1.0), (0.0, h - 0.05)]), 0.03 * cam.px_per_m(z), tint(_DARK, z), tid, Surface.PAINT)
        lamp_y = (0.4, 0.55)
    else:
        paint(_rect(-w / 2, 0.45 if kind is TRAM else 0.3, w / 2, h), colour, Surface.PAINT)
        paint(_rect(-w / 2 + 0.12, 1.25 if oncoming else 1.9, w / 2 - 0.12, h - (0.45 if oncoming else 0.3)), _GLASS,
              Surface.GLASS)
        if oncoming:
            paint(_rect(-w / 2 + 0.3, h - 0.4, w / 2 - 0.3, h - 0.12), (30, 25, 10), Surface.SMOOTH)
        if kind is TRAM:
            canvas.line(to_px([(-0.5, h), (0.3, h + 0.6), (-0.3, h + 1.2), (0.5, h + 1.2)]),
                        0.04 * cam.px_per_m(z), tint(_DARK, z), tid, Surface.PAINT)
        lamp_y = (0.75, 0.95)
    lamp = (250, 245, 225) if oncoming else (200, 20, 20)
    for sx in (-1, 1):
        paint(_rect(sx * (w / 2 - 0.22) - 0.14, lamp_y[0], sx * (w / 2 - 0.22) + 0.14, lamp_y[1]), lamp, Surface.SMOOTH)
    return covered


def _vehicle_side(canvas: Canvas, cam: Camera, tint: Tint, kind: VehicleKind, x_side: float, z: float,
                  colour: Colour) -> list[Point]:
    tid, length, h = TRAIN_ID[kind.name], kind.length_m, kind.height_m
    z_mid = z + length / 2
    body = cam.side(x_side, 0.28, 0.95 if kind is CAR else h, z, z + length)
    canvas.polygon(body, tint(colour, z_mid, 0.75), tid, Surface.PAINT)
    glass = tint(_GLASS, z_mid)
    if kind is CAR:
        canvas.polygon(cam.side(x_side, 0.95, h, z + 0.9, z + length - 1.1), tint(colour, z_mid, 0.7), tid,
                       Surface.PAINT)
        canvas.polygon(cam.side(x_side, 1.0, h - 0.08, z + 1.0, z + length - 1.3), glass, tid, Surface.GLASS)
    else:
        canvas.polygon(cam.side(x_side, 1.3, h - 0.35, z + 0.5, z + length - 0.5), glass, tid, Surface.GLASS)
    for zw in (z + 0.8, z + length - 0.8):
        u1, v1 = cam.project(x_side, 0.65, zw - 0.33)
        u2, v2 = cam.project(x_side, 0.0, zw + 0.33)
        canvas.ellipse((min(u1, u2), v1, max(u1, u2), v2), tint(_TYRE, zw), tid, Surface.RUBBER)
    return body


def draw_person(canvas: Canvas, cam: Camera, tint: Tint, rng: np.random.Generator, x: float, z: float,
                height_m: float) -> list[Point]:
    """Draw a standing or walking pedestrian (front or back view), ``height_m`` tall, feet at (x, 0, z)."""
    tid, s = TRAIN_ID["person"], height_m / 1.75
    top, trousers = _clothes(rng)
    skin = _SKINS[rng.integers(len(_SKINS))]
    stride = rng.uniform(0.0, 0.12)

    def to_px(points: Local) -> list[Point]:
        return cam.front(x, z, [(dx * s, y * s) for dx, y in points])

    for sx in (-1, 1):
        foot, hip = sx * (0.09 + stride), sx * 0.1
        canvas.polygon(to_px([(foot - 0.07, 0.0), (foot + 0.07, 0.0), (hip + 0.07, 0.86), (hip - 0.07, 0.86)]),
                       tint(trousers, z), tid, Surface.FABRIC)
        canvas.polygon(to_px([(sx * 0.21, 1.4), (sx * 0.29, 1.38), (sx * 0.31, 0.86), (sx * 0.23, 0.86)]),
                       tint(top, z, 0.85), tid, Surface.FABRIC)
    canvas.polygon(to_px([(-0.19, 0.84), (0.19, 0.84), (0.22, 1.43), (-0.22, 1.43)]), tint(top, z), tid,
                   Surface.FABRIC)
    canvas.ellipse(_ellipse(to_px, 0.0, 1.58, 0.1, 0.125), tint(skin, z), tid, Surface.PAINT)
    canvas.ellipse(_ellipse(to_px, 0.0, 1.64, 0.1, 0.07), tint((45, 35, 25), z), tid, Surface.FABRIC)
    return to_px([(-0.31, 0.0), (0.31, 1.71)])


def draw_two_wheeler(canvas: Canvas, cam: Camera, tint: Tint, rng: np.random.Generator, x: float, z: float,
                     motor: bool, ridden: bool, facing: int) -> list[Point]:
    """Draw a bicycle or motorcycle in side view heading along x (``facing`` +1 right, -1 left), maybe ridden."""
    tid, k = TRAIN_ID["motorcycle" if motor else "bicycle"], cam.px_per_m(z)

    def to_px(points: Local) -> list[Point]:
        return cam.front(x, z, [(facing * dx, y) for dx, y in points])

    r, g, b = (int(c) for c in rng.integers(30, 220, 3))
    frame = tint((r, g, b), z)
    hub, radius = (0.7, 0.31) if motor else (0.52, 0.34)
    for dx in (-hub, hub):
        box = _ellipse(to_px, dx, radius, radius, radius)
        if motor:
            canvas.ellipse(box, tint(_TYRE, z), tid, Surface.RUBBER)
            canvas.ellipse(_ellipse(to_px, dx, radius, 0.13, 0.13), tint((120, 120, 125), z), tid, Surface.PAINT)
        else:
            canvas.ring(box, 0.05 * k, tint(_TYRE, z), tid, Surface.RUBBER)
    if motor:
        canvas.polygon(to_px([(-0.75, 0.55), (-0.2, 0.35), (0.35, 0.35), (0.6, 0.75), (0.35, 0.95), (-0.1, 0.9),
                              (-0.8, 0.85)]), frame, tid, Surface.PAINT)
        canvas.line(to_px([(0.7, 0.31), (0.45, 1.05), (0.35, 1.1)]), 0.06 * k, tint(_DARK, z), tid, Surface.PAINT)
    else:
        canvas.line(to_px([(-0.52, 0.34), (-0.12, 0.82), (0.0, 0.3), (-0.52, 0.34)]), 0.04 * k, frame, tid,
                    Surface.PAINT)
        canvas.line(to_px([(-0.12, 0.82), (0.42, 0.86), (0.0, 0.3)]), 0.04 * k, frame, tid, Surface.PAINT)
        canvas.line(to_px([(0.52, 0.34), (0.4, 1.0), (0.3, 1.02)]), 0.035 * k, frame, tid, Surface.PAINT)
    covered = to_px([(-hub - radius, 0.0), (hub + radius, 1.1)])
    if ridden:
        covered += _rider(canvas, to_px, tint, rng, z, k, motor)
    return covered


def _rider(canvas: Canvas, to_px: ToPixels, tint: Tint, rng: np.random.Generator, z: float, k: float,
           motor: bool) -> list[Point]:
    tid = TRAIN_ID["rider"]
    top, trousers = _clothes(rng)
    seat, knee, foot = ((-0.25, 0.95), (0.2, 0.8), (0.25, 0.35)) if motor else ((-0.12, 0.9), (0.12, 0.62), (0.0, 0.3))
    shoulder, hand = (seat[0] + 0.25, seat[1] + 0.62), ((0.35, 1.1) if motor else (0.32, 1.02))
    canvas.line(to_px([seat, knee, foot]), 0.14 * k, tint(trousers, z), tid, Surface.FABRIC)
    canvas.line(to_px([seat, shoulder]), 0.3 * k, tint(top, z), tid, Surface.FABRIC)
    canvas.line(to_px([shoulder, hand]), 0.09 * k, tint(top, z, 0.85), tid, Surface.FABRIC)
    head = (25, 25, 30) if motor else _SKINS[rng.integers(len(_SKINS))]  # motorcyclists wear helmets
    canvas.ellipse(_ellipse(to_px, shoulder[0] + 0.06, shoulder[1] + 0.2, 0.12, 0.13), tint(head, z), tid,
                   Surface.PAINT)
    return to_px([(seat[0] - 0.15, seat[1]), (shoulder[0] + 0.2, shoulder[1] + 0.35)])


def draw_street_lamp(canvas: Canvas, cam: Camera, tint: Tint, x: float, z: float, towards: int) -> list[Point]:
    """Draw a 7 m lamp post whose arm reaches over the road (``towards`` +1 right, -1 left); all pole."""
    tid, grey = TRAIN_ID["pole"], tint((110, 112, 115), z)

    def to_px(points: Local) -> list[Point]:
        return cam.front(x, z, points)

    canvas.polygon(to_px([(-0.09, 0.0), (0.09, 0.0), (0.06, 7.0), (-0.06, 7.0)]), grey, tid, Surface.CONCRETE)
    canvas.line(to_px([(0.0, 6.9), (towards * 0.8, 7.2), (towards * 1.6, 7.2)]), 0.08 * cam.px_per_m(z), grey, tid,
                Surface.PAINT)
    canvas.polygon(to_px([(towards * 1.3, 7.1), (towards * 1.9, 7.1), (towards * 1.8, 7.3), (towards * 1.4, 7.3)]),
                   tint((200, 200, 190), z), tid, Surface.SMOOTH)
    return to_px([(-0.1, 0.0), (towards * 1.9, 7.3)])


def draw_traffic_light(canvas: Canvas, cam: Camera, tint: Tint, rng: np.random.Generator, x: float, z: float,
                       overhang_m: float) -> list[Point]:
    """Draw a traffic-light pole with a head on it and, if ``overhang_m`` != 0, a second head over the road."""
    pole, light = TRAIN_ID["pole"], TRAIN_ID["traffic light"]
    grey = tint((70, 72, 75), z)

    def to_px(points: Local) -> list[Point]:
        return cam.front(x, z, points)

    canvas.polygon(to_px(_rect(-0.07, 0.0, 0.07, 3.0)), grey, pole, Surface.PAINT)
    heads = [(0.0, 3.0)]
    if overhang_m:
        canvas.polygon(to_px(_rect(-0.06, 3.0, 0.06, 5.6)), grey, pole, Surface.PAINT)
        canvas.line(to_px([(0.0, 5.5), (overhang_m, 5.5)]), 0.1 * cam.px_per_m(z), grey, pole, Surface.PAINT)
        heads.append((overhang_m, 4.4))
    state = int(rng.integers(3))
    for hx, hy in heads:
        canvas.polygon(to_px(_rect(hx - 0.17, hy, hx + 0.17, hy + 1.0)), tint((25, 25, 25), z), light, Surface.PAINT)
        for i, (r, g, b) in enumerate(((255, 40, 30), (255, 190, 40), (60, 255, 120))):
            lamp = (r, g, b) if i == state else (r // 5, g // 5, b // 5)
            canvas.ellipse(_ellipse(to_px, hx, hy + 0.83 - 0.32 * i, 0.11, 0.11), tint(lamp, z), light, Surface.SMOOTH)
    return to_px([(-0.17, 0.0), (overhang_m + 0.17, 5.6 if overhang_m else 4.0)])


def draw_sign(canvas: Canvas, cam: Camera, tint: Tint, rng: np.random.Generator, x: float, z: float) -> list[Point]:
    """Draw a 2.6 m sign post (pole) with a round, triangular or square traffic sign."""
    tid = TRAIN_ID["traffic sign"]

    def to_px(points: Local) -> list[Point]:
        return cam.front(x, z, points)

    canvas.polygon(to_px(_rect(-0.04, 0.0, 0.04, 2.3)), tint((130, 130, 135), z), TRAIN_ID["pole"], Surface.PAINT)
    red, white, blue = tint((200, 20, 25), z), tint((240, 240, 240), z), tint((20, 70, 170), z)
    shape = int(rng.integers(3))
    if shape == 0:
        canvas.ellipse(_ellipse(to_px, 0.0, 2.6, 0.32, 0.32), red, tid, Surface.SMOOTH)
        canvas.ellipse(_ellipse(to_px, 0.0, 2.6, 0.24, 0.24), white, tid, Surface.SMOOTH)
    elif shape == 1:
        canvas.polygon(to_px([(-0.36, 2.3), (0.36, 2.3), (0.0, 2.92)]), red, tid, Surface.SMOOTH)
        canvas.polygon(to_px([(-0.25, 2.36), (0.25, 2.36), (0.0, 2.8)]), white, tid, Surface.SMOOTH)
    else:
        canvas.polygon(to_px(_rect(-0.3, 2.3, 0.3, 2.9)), blue, tid, Surface.SMOOTH)
        canvas.polygon(to_px([(-0.05, 2.38), (0.05, 2.38), (0.05, 2.65), (0.15, 2.65), (0.0, 2.82), (-0.15, 2.65),
                              (-0.05, 2.65)]), white, tid, Surface.SMOOTH)
    return to_px([(-0.36, 0.0), (0.36, 2.92)])


def draw_tree(canvas: Canvas, cam: Camera, tint: Tint, rng: np.random.Generator, x: float, z: float) -> list[Point]:
    """Draw a street tree: trunk and a canopy of overlapping blobs (all vegetation, as in Cityscapes)."""
    tid, size = TRAIN_ID["vegetation"], rng.uniform(0.8, 1.3)

    def to_px(points: Local) -> list[Point]:
        return cam.front(x, z, points)

    canvas.polygon(to_px([(-0.14, 0.0), (0.14, 0.0), (0.1, 3.2 * size), (-0.1, 3.2 * size)]), tint((85, 65, 45), z),
                   tid, Surface.CONCRETE)
    base = np.array([70, 105, 40]) * rng.uniform(0.7, 1.15)
    for _ in range(5):
        cx, cy = rng.normal(0.0, 0.7) * size, (3.8 + rng.normal(0.0, 0.6)) * size
        radius = rng.uniform(1.0, 1.7) * size
        r, g, b = (int(c) for c in np.clip(base * rng.uniform(0.75, 1.2), 0, 255))
        canvas.ellipse(_ellipse(to_px, cx, cy, radius, radius * 0.9), tint((r, g, b), z), tid, Surface.FOLIAGE)
    return to_px([(-2.6 * size, 0.0), (2.6 * size, 6.0 * size)])


def _clothes(rng: np.random.Generator) -> tuple[Colour, Colour]:
    i, j = rng.integers(len(_CLOTHES), size=2)
    return _CLOTHES[i], _CLOTHES[j]
