"""Pinhole camera over a flat ground plane, for laying out the synthetic street in metres."""

from __future__ import annotations

from dataclasses import dataclass

Point = tuple[float, float]


@dataclass(frozen=True)
class Camera:
    """Forward-looking pinhole camera ``height_m`` above the ground, optical axis level.

    World axes: x right, y up from the ground, z forward (all metres). ``focal_px`` and the
    principal point (``cx_px``, ``horizon_px``) are in pixels.
    """

    focal_px: float
    cx_px: float
    horizon_px: float
    height_m: float

    def project(self, x_m: float, y_m: float, z_m: float) -> Point:
        """Pixel (u, v) of world point (x, y, z); z must be > 0."""
        scale = self.focal_px / z_m
        return self.cx_px + scale * x_m, self.horizon_px + scale * (self.height_m - y_m)

    def px_per_m(self, z_m: float) -> float:
        """Pixels per metre of a fronto-parallel object at depth ``z_m``."""
        return self.focal_px / z_m

    def ground(self, x1_m: float, x2_m: float, z1_m: float, z2_m: float) -> list[Point]:
        """Quad of the ground rectangle [x1, x2] x [z1, z2]."""
        return [self.project(x1_m, 0.0, z1_m), self.project(x2_m, 0.0, z1_m),
                self.project(x2_m, 0.0, z2_m), self.project(x1_m, 0.0, z2_m)]

    def side(self, x_m: float, y1_m: float, y2_m: float, z1_m: float, z2_m: float) -> list[Point]:
        """Quad of the rectangle [y1, y2] x [z1, z2] in the plane x = x_m (facades, vehicle sides)."""
        return [self.project(x_m, y1_m, z1_m), self.project(x_m, y2_m, z1_m),
                self.project(x_m, y2_m, z2_m), self.project(x_m, y1_m, z2_m)]

    def front(self, x_m: float, z_m: float, points_m: list[tuple[float, float]]) -> list[Point]:
        """Pixels of points (dx, y) in the plane z = z_m, dx measured from x = x_m."""
        scale = self.focal_px / z_m
        u0, v0 = self.cx_px + scale * x_m, self.horizon_px + scale * self.height_m
        return [(u0 + scale * dx, v0 - scale * y) for dx, y in points_m]
