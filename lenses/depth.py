"""Where an object of known size sits when it covers a given number of sensor pixels."""

from __future__ import annotations

from lenses.spec import LensSpec


def sensor_distance_mm(spec: LensSpec) -> float:
    """Lens-to-sensor distance (mm) of a thin lens focused at the spec's focus distance."""
    f = spec.optics.focal_length_mm
    return 1.0 / (1.0 / f - 1.0 / (spec.optics.focus_distance_m * 1000.0))


def plate_distance_m(width_px: float, object_width_m: float, spec: LensSpec) -> float:
    """Object distance (m) at which an object `object_width_m` wide images to `width_px` pixels.

    Pinhole projection through the lens centre: width on the sensor = object width * z_s / z_o,
    z_s = `sensor_distance_mm`, divided by the pixel pitch.
    """
    if width_px <= 0 or object_width_m <= 0:
        raise ValueError(f"width_px and object_width_m must be > 0, got {width_px}, {object_width_m}")
    image_width_mm = width_px * spec.sensor.pixel_pitch_um / 1000.0
    return object_width_m * sensor_distance_mm(spec) / image_width_mm
