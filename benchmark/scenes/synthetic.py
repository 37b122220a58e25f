"""The ``synthetic`` scene set: procedural street scenes in Cityscapes' 19 train classes.

A scene is laid out in metres in front of a pinhole ``Camera`` (road with lanes, sidewalks,
terrain strips, facades with windows, a far skyline), populated with vehicles, people,
cyclists, poles, lights, signs and trees, and painted far-to-near so that nearer objects occlude
farther ones. Cars, trucks and buses carry plates of ``PLATE_FORMAT`` whose size follows the
perspective (about 8 px to 150 px wide at 512 x 1024; widths scale with the image width).
Everything is drawn from one ``numpy`` generator seeded with the scene seed.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from .camera import Camera, Point
from .canvas import Canvas, Colour, Surface
from .labels import TRAIN_ID
from common.plate_render import PLATE_SIZE_M, random_plate_text, render_plate
from .records import Box, Plate, Scene, Vehicle
from .street_objects import (BUS, CAR, TRAM, TRUCK, Tint, VehicleKind, draw_person, draw_sign, draw_street_lamp,
                             draw_traffic_light, draw_tree, draw_two_wheeler, draw_vehicle,
                             draw_vehicle_shadow)

LANE_WIDTH_M = 3.3
MAX_VEHICLE_DEPTH_M = 110.0

_CAR_COLOURS: tuple[Colour, ...] = ((225, 225, 225), (175, 178, 182), (28, 28, 32), (140, 20, 25), (25, 50, 115),
                                    (85, 90, 95), (30, 65, 45), (190, 160, 110), (230, 200, 40))
_FACADE_COLOURS: tuple[Colour, ...] = ((200, 188, 165), (165, 158, 150), (150, 85, 65), (215, 210, 195),
                                       (125, 118, 110), (180, 150, 110), (205, 195, 180), (110, 100, 95))


def generate_synthetic(size: tuple[int, int], seed: int, name: str) -> Scene:
    """Generate the street scene of ``seed`` at ``size = (H, W)`` pixels, with plate ground truth and plate mask."""
    return _Street(size, np.random.default_rng(seed)).build(seed, name)


class _Street:
    def __init__(self, size: tuple[int, int], rng: np.random.Generator) -> None:
        self.rng = rng
        self.height, self.width = size
        self.cam = Camera(focal_px=1.1 * self.width * rng.uniform(0.95, 1.05),
                          cx_px=self.width * rng.uniform(0.47, 0.53),
                          horizon_px=self.height * rng.uniform(0.36, 0.44), height_m=rng.uniform(1.15, 1.4))
        overcast = rng.random() < 0.35
        top, bottom = ((150, 158, 168), (215, 220, 225)) if overcast else ((60, 110, 185), (185, 205, 230))
        self.tint = Tint(haze=bottom, visibility_m=rng.uniform(150.0, 400.0))
        self.canvas = Canvas(size, top, bottom, TRAIN_ID["sky"])
        n_lanes = int(rng.integers(2, 5))
        self.ego_lane = int(rng.integers(n_lanes))
        self.road = (-LANE_WIDTH_M * (self.ego_lane + 0.5), LANE_WIDTH_M * (n_lanes - self.ego_lane - 0.5))
        self.n_lanes = n_lanes
        self.oncoming_lanes = int(rng.integers(0, self.ego_lane + 1))
        self.crosswalk_z = rng.uniform(10.0, 35.0) if rng.random() < 0.5 else None
        self.objects: list[tuple[float, Callable[[], None]]] = []
        self.sidewalk: dict[int, tuple[float, float]] = {}
        self.vehicles: list[Vehicle] = []
        self.plates: list[tuple[str, Box, int, int]] = []

    def build(self, seed: int, name: str) -> Scene:
        self._skyline()
        self._ground()
        for side in (-1, 1):
            self._facades(side)
        self._place_vehicles()
        self._place_people_and_furniture()
        for _, draw in sorted(self.objects, key=lambda item: -item[0]):
            draw()
        image, labels, plate_map = self.canvas.finish(self.rng, exposure=self.rng.uniform(0.85, 1.05))
        plates, plate_map = self._visible_plates(plate_map)
        return Scene(image, labels, plates, self.vehicles, seed, name, plate_map)

    # -- background -------------------------------------------------------------------------

    def _skyline(self) -> None:
        z = 250.0
        k = self.cam.px_per_m(z)
        x = -self.cam.cx_px / k - 10.0
        while x < (self.width - self.cam.cx_px) / k:
            span = self.rng.uniform(10.0, 35.0)
            if self.rng.random() < 0.3:
                r = span / 2
                self.canvas.ellipse(_bbox(self.cam.front(x + r, z, [(-r, 0.0), (r, self.rng.uniform(8.0, 18.0))])),
                                    self.tint((70, 100, 50), z, 1.5), TRAIN_ID["vegetation"], Surface.FOLIAGE)
            else:
                colour = _FACADE_COLOURS[self.rng.integers(len(_FACADE_COLOURS))]
                self.canvas.polygon(_rect(self.cam, x, z, span, self.rng.uniform(8.0, 40.0)),
                                    self.tint(colour, z, 0.9), TRAIN_ID["building"], Surface.PLASTER)
            x += span

    def _ground(self) -> None:
        cam, canvas, tint = self.cam, self.canvas, self.tint
        canvas.polygon([(0, cam.horizon_px), (self.width, cam.horizon_px), (self.width, self.height), (0, self.height)],
                       tint((150, 148, 142), 30.0), TRAIN_ID["sidewalk"], Surface.CONCRETE)
        left, right = self.road
        asphalt = tint((88, 88, 92), 20.0)
        canvas.polygon(cam.ground(left, right, 0.5, 2000.0), asphalt, TRAIN_ID["road"], Surface.ASPHALT)
        for x_edge in (left, right):
            canvas.polygon(cam.ground(x_edge - 0.15, x_edge + 0.15, 0.5, 2000.0), tint((175, 172, 165), 20.0),
                           TRAIN_ID["sidewalk"], Surface.CONCRETE)
        self._lane_markings()

    def _lane_markings(self) -> None:
        left, right = self.road
        white, yellow = self.tint((225, 225, 220), 15.0), self.tint((225, 190, 60), 15.0)
        road_id = TRAIN_ID["road"]
        for lane in range(1, self.n_lanes):
            x = left + lane * LANE_WIDTH_M
            if lane == self.oncoming_lanes:
                for dx in (-0.12, 0.12):
                    self.canvas.polygon(self.cam.ground(x + dx - 0.06, x + dx + 0.06, 1.0, 400.0), yellow, road_id,
                                        Surface.SMOOTH)
                continue
            for z in np.arange(self.rng.uniform(1.0, 9.0), 150.0, 9.0):
                self.canvas.polygon(self.cam.ground(x - 0.07, x + 0.07, z, z + 3.0), white, road_id, Surface.SMOOTH)
        for x in (left + 0.3, right - 0.3):
            self.canvas.polygon(self.cam.ground(x - 0.08, x + 0.08, 1.0, 400.0), white, road_id, Surface.SMOOTH)
        if self.crosswalk_z is not None:
            for x in np.arange(left + 0.5, right - 0.5, 1.0):
                self.canvas.polygon(self.cam.ground(x, x + 0.5, self.crosswalk_z, self.crosswalk_z + 3.5), white,
                                    road_id, Surface.SMOOTH)

    def _facades(self, side: int) -> None:
        """Buildings along one side (side = -1 left, +1 right), far to near, with occasional gaps."""
        rng = self.rng
        curb = self.road[1] if side > 0 else self.road[0]
        sidewalk_m = rng.uniform(2.5, 5.0)
        terrain_m = rng.uniform(1.5, 3.5) if rng.random() < 0.6 else 0.0
        self.sidewalk[side] = (curb, curb + side * sidewalk_m)
        facade_x = curb + side * (sidewalk_m + terrain_m)
        if terrain_m:
            x1, x2 = sorted((curb + side * sidewalk_m, facade_x))
            self.canvas.polygon(self.cam.ground(x1, x2, 0.5, 400.0), self.tint((95, 120, 55), 20.0),
                                TRAIN_ID["terrain"], Surface.GRASS)
        segments = []
        z = 0.5
        end = rng.uniform(100.0, 200.0)
        while z < end:
            length = rng.uniform(8.0, 28.0)
            segments.append((z, z + length))
            z += length
        for z1, z2 in reversed(segments):
            x = facade_x + side * rng.uniform(0.0, 1.2)
            # A gap right beside the camera would fill the frame with one bush.
            if z1 > 8.0 and rng.random() < 0.25:
                self._gap(x, z1, z2, side)
            else:
                self._building(x, z1, z2, side)
        if terrain_m and rng.random() < 0.7:
            for z in np.arange(rng.uniform(6.0, 15.0), end, rng.uniform(8.0, 16.0)):
                x_tree = (curb + side * sidewalk_m + facade_x) / 2
                self.objects.append((z, lambda x=x_tree, z=z: draw_tree(self.canvas, self.cam, self.tint, rng, x, z)))

    def _building(self, x: float, z1: float, z2: float, side: int) -> None:
        rng, cam = self.rng, self.cam
        height = rng.uniform(7.0, 30.0)
        colour = _FACADE_COLOURS[rng.integers(len(_FACADE_COLOURS))]
        light = 1.0 if side > 0 else 0.8
        z_mid = (z1 + z2) / 2
        self.canvas.polygon(cam.side(x, 0.0, height, z1, z2), self.tint(colour, z_mid, light), TRAIN_ID["building"],
                            Surface.PLASTER)
        glass = self.tint((55, 65, 78), z_mid, light)
        lit = self.tint((200, 180, 120), z_mid)
        floor_m, spacing_m = rng.uniform(3.0, 3.6), rng.uniform(2.5, 4.0)
        # Windows narrower than about a pixel only cost time.
        if cam.px_per_m(z2) * 1.2 * abs(x) / z2 >= 0.5:
            for y in np.arange(3.6, height - 1.6, floor_m):
                for zw in np.arange(z1 + 1.0, z2 - 1.8, spacing_m):
                    self.canvas.polygon(cam.side(x, y, y + 1.6, zw, zw + 1.2), lit if rng.random() < 0.08 else glass,
                                        TRAIN_ID["building"], Surface.GLASS)
        self.canvas.polygon(cam.side(x, 0.3, 2.8, z1 + 0.8, z2 - 0.8), self.tint((40, 45, 50), z_mid, light),
                            TRAIN_ID["building"], Surface.GLASS)

    def _gap(self, x: float, z1: float, z2: float, side: int) -> None:
        """A gap between buildings: a wall or fence in front of bushes and a set-back building."""
        rng, cam, canvas, tint = self.rng, self.cam, self.canvas, self.tint
        z_mid = (z1 + z2) / 2
        canvas.polygon(cam.side(x + side * 15.0, 0.0, rng.uniform(8.0, 20.0), z1, z2 + 15.0),
                       tint(_FACADE_COLOURS[rng.integers(len(_FACADE_COLOURS))], z_mid, 0.85), TRAIN_ID["building"],
                       Surface.PLASTER)
        x1, x2 = sorted((x, x + side * 15.0))
        canvas.polygon(cam.ground(x1, x2, z1, z2), tint((95, 120, 55), z_mid), TRAIN_ID["terrain"], Surface.GRASS)
        for zb in np.arange(z1 + 2.0, z2, 3.0):
            r = cam.px_per_m(zb) * rng.uniform(1.5, 2.5)
            u, v = cam.project(x + side * 3.0, rng.uniform(2.5, 4.5), zb)
            canvas.ellipse((u - r, v - r, u + r, v + r), tint((60, 95, 40), zb, rng.uniform(0.8, 1.2)),
                           TRAIN_ID["vegetation"], Surface.FOLIAGE)
        wall_h = rng.uniform(1.0, 2.4)
        if rng.random() < 0.5:
            canvas.polygon(cam.side(x, 0.0, wall_h, z1, z2), tint((165, 160, 150), z_mid, 0.9), TRAIN_ID["wall"],
                           Surface.CONCRETE)
            return
        grey, fence = tint((120, 120, 118), z_mid), TRAIN_ID["fence"]
        width = 0.05 * cam.px_per_m(z2)
        for y in (0.3, wall_h - 0.1):
            canvas.line([cam.project(x, y, z1), cam.project(x, y, z2)], width, grey, fence, Surface.PAINT)
        for zp in np.arange(z1, z2, 0.6):
            canvas.line([cam.project(x, 0.0, zp), cam.project(x, wall_h, zp)], 0.04 * cam.px_per_m(zp), grey, fence,
                        Surface.PAINT)

    # -- objects ----------------------------------------------------------------------------

    def _place_vehicles(self) -> None:
        rng = self.rng
        tram_lane = int(rng.integers(self.n_lanes)) if rng.random() < 0.25 else -1
        for lane in range(self.n_lanes):
            x_lane = self.road[0] + (lane + 0.5) * LANE_WIDTH_M
            z = rng.uniform(3.6, 9.0) if lane == self.ego_lane else rng.uniform(3.0, 25.0)
            while z < MAX_VEHICLE_DEPTH_M:
                kind = TRAM if lane == tram_lane else ((CAR,) * 8 + (TRUCK, BUS))[rng.integers(10)]
                z = max(z, kind.min_depth_m)
                tram_lane = -1 if kind is TRAM else tram_lane
                if kind is TRAM or rng.random() < 0.8:
                    x, oncoming = x_lane + rng.uniform(-0.3, 0.3), lane < self.oncoming_lanes
                    self._schedule_vehicle(kind, x, z, oncoming)
                z += kind.length_m + rng.uniform(3.0, 30.0)
        for curb, side in ((self.road[0], -1), (self.road[1], 1)):
            if rng.random() < 0.5:
                continue
            # Cars parked half on the sidewalk, a common sight in European streets.
            for z in np.arange(rng.uniform(4.0, 15.0), 70.0, CAR.length_m + rng.uniform(1.0, 8.0)):
                if rng.random() < 0.7:
                    self._schedule_vehicle(CAR, curb + side * 0.7, z, False)

    def _schedule_vehicle(self, kind: VehicleKind, x: float, z: float, oncoming: bool) -> None:
        draw_vehicle_shadow(self.canvas, self.cam, self.tint, kind, x, z)
        self.objects.append((z, lambda: self._vehicle(kind, x, z, oncoming)))

    def _vehicle(self, kind: VehicleKind, x: float, z: float, oncoming: bool) -> None:
        colour = _CAR_COLOURS[self.rng.integers(len(_CAR_COLOURS))]
        covered = draw_vehicle(self.canvas, self.cam, self.tint, kind, x, z, colour, oncoming)
        box = self._clip(_bbox(covered))
        if box is None:
            return
        self.vehicles.append(Vehicle(TRAIN_ID[kind.name], box))
        if kind is not TRAM:
            self._plate(x, kind.plate_y_m, z, len(self.vehicles) - 1, TRAIN_ID[kind.name])

    def _plate(self, x: float, y: float, z: float, vehicle_index: int, train_id: int) -> None:
        k = self.cam.px_per_m(z)
        width, height = round(PLATE_SIZE_M[0] * k), round(PLATE_SIZE_M[1] * k)
        text = random_plate_text(self.rng)
        background = (236, 236, 228) if self.rng.random() < 0.8 else (240, 210, 40)
        eu_band = bool(self.rng.random() < 0.5)
        plate_id = len(self.plates) + 1
        # Below 2 px high a plate is a smudge with no text to speak of; keep ids within uint8.
        if height < 2 or plate_id > 255:
            return
        u, v = self.cam.project(x, y, z - 0.02)
        x1, y1 = round(u - width / 2), round(v - height / 2)
        full = (x1, y1, x1 + width, y1 + height)
        if self._clip(full) is None:
            return
        image = render_plate(text, (width, height), self.tint(background, z), eu_band)
        self.canvas.plate(image, (x1, y1), plate_id, train_id)
        self.plates.append((text, full, vehicle_index, width * height))

    def _place_people_and_furniture(self) -> None:
        rng, cam, canvas, tint = self.rng, self.cam, self.canvas, self.tint
        add = self.objects.append
        for side, (curb, outer) in self.sidewalk.items():
            x_lo, x_hi = sorted((curb + side * 0.5, outer - side * 0.4))
            for _ in range(rng.integers(1, 7)):
                x, z, h = rng.uniform(x_lo, x_hi), rng.uniform(4.0, 70.0), rng.uniform(1.55, 1.95)
                add((z, lambda x=x, z=z, h=h: draw_person(canvas, cam, tint, rng, x, z, h)))
            lamp_x = curb + side * 0.5
            for z in np.arange(rng.uniform(4.0, 20.0), 160.0, rng.uniform(20.0, 32.0)):
                add((z, lambda x=lamp_x, z=z, s=side: draw_street_lamp(canvas, cam, tint, x, z, -s)))
            for _ in range(rng.integers(0, 3)):
                x, z = curb + side * 0.4, rng.uniform(8.0, 60.0)
                add((z, lambda x=x, z=z: draw_sign(canvas, cam, tint, rng, x, z)))
            if rng.random() < 0.4:
                x, z = outer - side * 0.8, rng.uniform(4.0, 40.0)
                self._two_wheeler(x, z, bool(rng.random() < 0.4), ridden=False)
        right = self.road[1]
        light_z = self.crosswalk_z if self.crosswalk_z is not None else rng.uniform(12.0, 45.0)
        add((light_z, lambda: draw_traffic_light(canvas, cam, tint, rng, right + 0.5, light_z, -LANE_WIDTH_M)))
        if self.crosswalk_z is not None:
            for _ in range(rng.integers(0, 4)):
                x, z = rng.uniform(*self.road), self.crosswalk_z + rng.uniform(0.3, 3.0)
                add((z, lambda x=x, z=z: draw_person(canvas, cam, tint, rng, x, z, rng.uniform(1.55, 1.95))))
        for _ in range(rng.integers(1, 4)):
            x, z = rng.uniform(*self.road), rng.uniform(8.0, 60.0)
            self._two_wheeler(x, z, bool(rng.random() < 0.4), ridden=True)

    def _two_wheeler(self, x: float, z: float, motor: bool, ridden: bool) -> None:
        facing = 1 if self.rng.random() < 0.5 else -1
        train_id = TRAIN_ID["motorcycle" if motor else "bicycle"]

        def draw() -> None:
            covered = draw_two_wheeler(self.canvas, self.cam, self.tint, self.rng, x, z, motor, ridden, facing)
            box = self._clip(_bbox(covered))
            if box is not None:
                self.vehicles.append(Vehicle(train_id, box))

        self.objects.append((z, draw))

    # -- ground truth -----------------------------------------------------------------------

    def _clip(self, box: tuple[float, float, float, float]) -> Box | None:
        x1, y1 = max(0, int(np.floor(box[0]))), max(0, int(np.floor(box[1])))
        x2, y2 = min(self.width, int(np.ceil(box[2]))), min(self.height, int(np.ceil(box[3])))
        return (x1, y1, x2, y2) if x2 > x1 and y2 > y1 else None

    def _visible_plates(self, plate_map: np.ndarray) -> tuple[list[Plate], np.ndarray]:
        counts = np.bincount(plate_map.ravel(), minlength=256)
        renumber = np.zeros(256, dtype=np.uint8)
        plates: list[Plate] = []
        for old_id, (text, full, vehicle_index, area) in enumerate(self.plates, start=1):
            if counts[old_id] == 0:
                continue
            box = self._clip(full)
            assert box is not None, "plates outside the image are never drawn"
            plates.append(Plate(text, box, vehicle_index, float(counts[old_id]) / area))
            renumber[old_id] = len(plates)
        return plates, renumber[plate_map]


def _bbox(points: list[Point]) -> tuple[float, float, float, float]:
    us, vs = [p[0] for p in points], [p[1] for p in points]
    return min(us), min(vs), max(us), max(vs)


def _rect(cam: Camera, x: float, z: float, width_m: float, height_m: float) -> list[Point]:
    return cam.front(x, z, [(0.0, 0.0), (width_m, 0.0), (width_m, height_m), (0.0, height_m)])
