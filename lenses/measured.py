"""A measured PSF as the lens's optics: images read from untrusted files, checked, resampled to the sensor.

A measured PSF is one image per colour channel (R, G, B) or one image for all three (a 2-D image, or one
holding the three channels), each pixel the energy a point source put into that pixel of the sensor it
was measured on, whose pitch the spec states. Files are read without executing anything: ``.npy``
through ``numpy.load(allow_pickle=False)``, TIFF and PNG through Pillow (32-bit float, 16-bit and 8-bit
grey, 8-bit RGB). Nothing here corrects the data: an image with a NaN, an infinity or a negative value is
refused (subtract the dark frame and clip before), not repaired.

The optical axis lies at the image's geometric centre (the centre of pixel M // 2 of an odd side M, the
corner between the two middle pixels of an even one); the PSF is not re-centred. Resampling to the
sensor pitch treats each measured pixel as a uniform square of energy and gives each sensor pixel the
energy of the parts that overlap it (`overlap_matrix`): exact when the measured pixels tile the sensor
pixels (an integer ratio with aligned edges: a side of 2K pixels at half the pitch of an odd K), a box
interpolation otherwise.
"""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

import numpy as np

IMAGE_SUFFIXES = (".npy", ".tif", ".tiff", ".png")
MAX_IMAGE_SIDE_PX = 8192  # a PSF image larger than this is refused before it is decoded


def sha256_of(path: Path) -> str:
    """Hex SHA-256 of a file's bytes: what a spec's cache key holds of the file's content."""
    return hashlib.sha256(path.read_bytes()).hexdigest()


def read_image(path: Path) -> np.ndarray:
    """A 2-D (H, W) or 3-channel (3, H, W) float64 image from ``path``; ValueError saying why not.

    Raises ValueError for an unreadable file or one that is not a real-valued image of 1 or 3 channels.
    """
    suffix = path.suffix.lower()
    if suffix not in IMAGE_SUFFIXES:
        raise ValueError(f"has the suffix {suffix!r}; valid: {', '.join(IMAGE_SUFFIXES)}")
    if suffix == ".npy":
        try:
            array = np.load(path, allow_pickle=False, mmap_mode="r")  # the shape is checked before reading
        except (ValueError, OSError, EOFError) as exc:  # not .npy, truncated, or an object array (pickle)
            raise ValueError(f"is not a numeric .npy array numpy reads without pickle ({exc})") from None
        if not isinstance(array, np.ndarray) or array.dtype.kind not in "fiu":
            raise ValueError(f"holds {getattr(array, 'dtype', type(array).__name__)} data; valid: real numbers")
        if array.ndim >= 2 and max(array.shape[-2:]) > MAX_IMAGE_SIDE_PX:
            raise ValueError(f"has shape {array.shape}; valid: at most {MAX_IMAGE_SIDE_PX} pixels a side")
    else:
        from PIL import Image, UnidentifiedImageError
        try:
            with Image.open(path) as image:
                if max(image.size) > MAX_IMAGE_SIDE_PX:
                    raise ValueError(f"is {image.size[0]} x {image.size[1]} pixels; valid: at most {MAX_IMAGE_SIDE_PX} a side")
                image.load()
                mode = image.mode
                array = np.asarray(image.convert("F") if mode in ("I", "I;16", "I;16B", "I;16L") else image)
        except (UnidentifiedImageError, Image.DecompressionBombError, OSError) as exc:
            raise ValueError(f"is not an image Pillow reads ({exc})") from None
        if array.ndim == 3:
            array = np.moveaxis(array, -1, 0)  # Pillow's (H, W, C) to (C, H, W)
    array = np.asarray(array, dtype=np.float64)
    if array.ndim == 3 and array.shape[0] not in (1, 3) and array.shape[-1] in (1, 3):
        array = np.moveaxis(array, -1, 0)  # an (H, W, C) array
    if array.ndim == 3 and array.shape[0] == 1:
        array = array[0]
    if array.ndim not in (2, 3) or (array.ndim == 3 and array.shape[0] != 3):
        raise ValueError(f"has shape {array.shape}: {array.shape[0] if array.ndim == 3 else 'no'} channels; "
                         "valid: a 2-D image or one of 3 channels (R, G, B)")
    if min(array.shape[-2:]) < 1:
        raise ValueError(f"is empty (shape {array.shape})")
    return array


def check_psf(array: np.ndarray) -> None:
    """Raise ValueError unless every value is finite and >= 0 and every channel holds some energy."""
    bad = int((~np.isfinite(array)).sum())
    if bad:
        raise ValueError(f"has {bad} NaN or infinite values; valid: finite values >= 0")
    negative = int((array < 0).sum())
    if negative:
        raise ValueError(f"has {negative} negative values (lowest {float(array.min()):.3g}); valid: values >= 0 "
                         "(subtract the dark frame and clip at 0 before)")
    sums = array.reshape(-1, *array.shape[-2:]).sum(axis=(1, 2))
    if not bool((sums > 0).all()):
        raise ValueError("has a channel that is zero everywhere; valid: some energy in every channel")


def read_psf_channels(paths: list[Path]) -> np.ndarray:
    """The (3, H, W) float64 PSF from one file (a 2-D image used for all three channels, or a 3-channel
    one) or three (R, G, B; 2-D images of one shape). ValueError naming the file index: "[i] ...".
    """
    if len(paths) not in (1, 3):
        raise ValueError(f"has {len(paths)} files; valid: 1 (one image for all three channels, or one holding "
                         "R, G, B) or 3 (R, G, B)")
    images = []
    for i, path in enumerate(paths):
        try:
            image = read_image(path)
            check_psf(image)
        except ValueError as exc:
            raise ValueError(f"[{i}] ({path}) {exc}") from None
        if len(paths) == 3 and image.ndim != 2:
            raise ValueError(f"[{i}] ({path}) holds 3 channels, but 3 files give one channel each; valid: a 2-D "
                             "image per file, or one file holding all three")
        images.append(image)
    if len(paths) == 1:
        return images[0] if images[0].ndim == 3 else np.stack([images[0]] * 3)
    if len({im.shape for im in images}) != 1:
        raise ValueError(f"holds images of different shapes {[im.shape for im in images]}; valid: one shape")
    return np.stack(images)


def output_size_px(measured_px: int, measured_pitch_um: float, sensor_pitch_um: float) -> int:
    """Smallest odd number of sensor pixels, centred on the axis, that covers `measured_px` measured ones."""
    k = math.ceil(measured_px * measured_pitch_um / sensor_pitch_um - 1e-9)
    return k if k % 2 == 1 else k + 1


def overlap_matrix(measured_px: int, measured_pitch_um: float, size_px: int, sensor_pitch_um: float) -> np.ndarray:
    """R (size_px, measured_px): the fraction of measured pixel i that falls into sensor pixel k.

    Measured pixel i spans (i - M/2, i + 1 - M/2) x measured pitch, sensor pixel k spans
    (k - K//2 -/+ 1/2) x sensor pitch (pixel K//2 centred on the axis); R[k, i] is the length of their
    overlap over the measured pitch. A (H, W) energy image P becomes R_y P R_x^T.
    """
    lo_in = (np.arange(measured_px) - measured_px / 2) * measured_pitch_um
    hi_in = lo_in + measured_pitch_um
    centres = (np.arange(size_px) - size_px // 2) * sensor_pitch_um
    lo_out, hi_out = centres - sensor_pitch_um / 2, centres + sensor_pitch_um / 2
    overlap = np.minimum(hi_out[:, None], hi_in[None, :]) - np.maximum(lo_out[:, None], lo_in[None, :])
    return np.clip(overlap, 0.0, None) / measured_pitch_um


def sensor_psf(measured: np.ndarray, measured_pitch_um: float, sensor_pitch_um: float, max_size_px: int
               ) -> tuple[np.ndarray, np.ndarray]:
    """The measured (3, H, W) energies on the sensor grid: PSF (3, K, K), each channel summing to 1, and the
    energy fraction (3,) of the measured image that lies inside it.

    K is the odd size covering the measured image at the sensor pitch, cut to `max_size_px` (centred) if
    larger; the fraction is what the cut leaves (1 when nothing is cut).
    """
    height, width = measured.shape[-2:]
    k = min(max(output_size_px(height, measured_pitch_um, sensor_pitch_um),
                output_size_px(width, measured_pitch_um, sensor_pitch_um)), max_size_px)
    if height == width == k and measured_pitch_um == sensor_pitch_um:
        pixels = measured.copy()  # already on the sensor grid: used as given
    else:
        rows = overlap_matrix(height, measured_pitch_um, k, sensor_pitch_um)
        cols = overlap_matrix(width, measured_pitch_um, k, sensor_pitch_um)
        pixels = rows @ measured @ cols.T
    inside = pixels.sum(axis=(1, 2))
    fraction = inside / measured.sum(axis=(1, 2))
    return pixels / inside[:, None, None], np.minimum(fraction, 1.0)
