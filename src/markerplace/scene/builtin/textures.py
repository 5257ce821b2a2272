"""Texture images for procedural interiors: numpy generators and photos bundled with scikit-image.

Every generator takes a ``numpy.random.Generator`` and returns a (H, W, 3) uint8 RGB image
(row 0 = top) that tiles horizontally and vertically unless stated otherwise. Photos come only from
image files shipped inside the installed scikit-image package (read directly, never downloaded);
when one is missing a procedural picture is used instead.

:class:`TextureBank` memoizes textures by key within one scene build, so repeated items share one
read-only array object, and derives each texture's generator from (seed, key) so a texture does not
depend on the order in which textures are requested.
"""

from __future__ import annotations

import logging
import zlib
from importlib import resources
from typing import Callable

import numpy as np

log = logging.getLogger(__name__)

# Photos shipped inside scikit-image (file names in skimage/data); verified to load offline.
BUNDLED_PHOTOS = {
    "astronaut": "astronaut.png",
    "coffee": "coffee.png",
    "chelsea": "chelsea.png",
    "rocket": "rocket.jpg",
    "camera": "camera.png",
    "brick": "brick.png",
    "grass": "grass.png",
    "gravel": "gravel.png",
    "coins": "coins.png",
    "moon": "moon.png",
    "page": "page.png",
    "text": "text.png",
    "clock": "clock_motion.png",
    "hubble": "hubble_deep_field.jpg",
    "ihc": "ihc.png",
    "logo": "logo.png",
    "retina": "retina.jpg",
    "motorcycle": "motorcycle_left.png",
    "color": "color.png",
}


class TextureBank:
    """Per-build memo of textures: ``bank.get(key, fn, *args)`` returns one shared read-only array.

    ``fn(rng, *args)`` is called once per key with ``rng = default_rng([seed, crc32(key)])``.
    """

    def __init__(self, seed: int):
        self.seed = int(seed)
        self._cache: dict[str, np.ndarray] = {}

    def get(self, key: str, fn: Callable[..., np.ndarray], *args, **kwargs) -> np.ndarray:
        if key not in self._cache:
            rng = np.random.default_rng([self.seed & 0xFFFFFFFF, zlib.crc32(key.encode())])
            img = np.ascontiguousarray(fn(rng, *args, **kwargs), dtype=np.uint8)
            assert img.ndim == 3 and img.shape[2] == 3, key
            img.flags.writeable = False
            self._cache[key] = img
        return self._cache[key]

    def __len__(self) -> int:
        return len(self._cache)


# ----------------------------------------------------------------------------------------------
# helpers


def _to_u8(img: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def value_noise(rng: np.random.Generator, size: int, cells: int, octaves: int = 4) -> np.ndarray:
    """Tileable fractal value noise, (size, size) float in about [0, 1].

    ``cells`` is the number of lattice cells across the image at the coarsest octave.
    """
    out = np.zeros((size, size))
    amp, total = 1.0, 0.0
    for o in range(octaves):
        n = min(cells * (2**o), size)
        grid = rng.random((n, n))
        t = np.arange(size) * n / size
        i0 = np.floor(t).astype(int)
        f = t - i0
        f = f * f * (3 - 2 * f)
        i1 = (i0 + 1) % n
        i0 = i0 % n
        rows = grid[i0][:, i0] * (1 - f)[None, :] + grid[i0][:, i1] * f[None, :]
        rows1 = grid[i1][:, i0] * (1 - f)[None, :] + grid[i1][:, i1] * f[None, :]
        out += amp * (rows * (1 - f)[:, None] + rows1 * f[:, None])
        total += amp
        amp *= 0.5
    return out / total


def _tint(gray: np.ndarray, color) -> np.ndarray:
    """(H, W) float in [0, 1] brightness and an RGB colour (0-255) -> (H, W, 3) float."""
    return gray[..., None] * np.asarray(color, dtype=float)[None, None, :]


def _resize(img: np.ndarray, width: int, height: int) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.fromarray(img).resize((int(width), int(height)), Image.BILINEAR))


# ----------------------------------------------------------------------------------------------
# surfaces


def painted_wall(rng: np.random.Generator, color=(232, 228, 218), size: int = 128, amplitude: float = 2.0) -> np.ndarray:
    """Matte painted plaster: a flat colour with very subtle noise (+- ``amplitude`` levels).

    Deliberately almost textureless: these are the stretches where markers help.
    """
    n = value_noise(rng, size, 4, octaves=3) - 0.5
    return _to_u8(np.asarray(color, dtype=float)[None, None, :] + 2.0 * amplitude * n[..., None])


def wood_planks(rng: np.random.Generator, size: int = 512, planks: int = 4, color=(150, 105, 65)) -> np.ndarray:
    """Wooden floor boards running along u: ``planks`` rows, staggered end joints, grain, dark gaps."""
    y, x = np.mgrid[0:size, 0:size].astype(float)
    img = np.zeros((size, size, 3))
    h = size // planks
    grain_noise = value_noise(rng, size, 8, octaves=3)
    for p in range(planks):
        rows = slice(p * h, (p + 1) * h)
        tone = 0.8 + 0.35 * rng.random()
        joint = rng.integers(0, size)
        yy = y[rows] - p * h
        xx = (x[rows] - joint) % size
        rings = np.sin(0.35 * yy + 6.0 * grain_noise[rows] + 0.01 * xx * rng.uniform(0.5, 1.5))
        streak = 0.85 + 0.1 * rings + 0.08 * (value_noise(rng, size, 32, octaves=2)[rows] - 0.5)
        board = _tint(streak * tone, color)
        board[xx < 2] *= 0.35  # end joint
        board[(yy < 2) | (yy > h - 2)] *= 0.4  # gaps between boards
        img[rows] = board
    return _to_u8(img)


def wood_grain(rng: np.random.Generator, size: int = 256, color=(160, 110, 70)) -> np.ndarray:
    """Furniture wood (veneer): fine grain lines along u with knots of darker tone."""
    n = value_noise(rng, size, 4, octaves=4)
    y = np.arange(size, dtype=float)[:, None]
    lines = np.sin(y * 0.6 + 12.0 * n) * 0.5 + 0.5
    fine = value_noise(rng, size, 64, octaves=1)
    gray = 0.75 + 0.18 * lines + 0.1 * (fine - 0.5)
    return _to_u8(_tint(gray, color))


def floor_tiles(rng: np.random.Generator, size: int = 512, n: int = 4, color=(205, 200, 190), grout=(120, 115, 110)) -> np.ndarray:
    """Ceramic floor tiles: ``n`` x ``n`` tiles, each with its own tone and mottling, grout lines."""
    tile = size // n
    speck = value_noise(rng, size, 48, octaves=2)
    tones = 0.88 + 0.14 * rng.random((n, n))
    gray = np.kron(tones, np.ones((tile, tile)))[:size, :size] * (0.92 + 0.16 * (speck - 0.5))
    img = _tint(gray, color)
    y, x = np.mgrid[0:size, 0:size]
    mask = ((x % tile) < 3) | ((y % tile) < 3)
    img[mask] = grout
    return _to_u8(img)


def carpet(rng: np.random.Generator, size: int = 256, color=(95, 100, 120)) -> np.ndarray:
    """Office carpet tiles: fine pile noise over a faint square pattern."""
    pile = rng.random((size, size))
    blotch = value_noise(rng, size, 6, octaves=3)
    y, x = np.mgrid[0:size, 0:size]
    squares = 0.04 * (((x // (size // 2)) + (y // (size // 2))) % 2)
    gray = 0.8 + 0.18 * (pile - 0.5) + 0.2 * (blotch - 0.5) + squares
    return _to_u8(_tint(gray, color))


def ceiling_tiles(rng: np.random.Generator, size: int = 256, n: int = 4) -> np.ndarray:
    """Acoustic ceiling tiles: off-white, pinhole speckle, metal grid between tiles."""
    tile = size // n
    holes = rng.random((size, size)) < 0.03
    gray = 0.93 + 0.03 * (value_noise(rng, size, 16, octaves=2) - 0.5) - 0.25 * holes
    img = _tint(gray, (240, 238, 232))
    y, x = np.mgrid[0:size, 0:size]
    img[((x % tile) < 3) | ((y % tile) < 3)] = (170, 170, 168)
    return _to_u8(img)


def fabric(rng: np.random.Generator, size: int = 128, color=(70, 90, 140)) -> np.ndarray:
    """Woven upholstery: a fine over-under weave with slight colour variation."""
    y, x = np.mgrid[0:size, 0:size]
    weave = 0.5 + 0.5 * np.sin(x * np.pi / 2) * np.sin(y * np.pi / 2)
    gray = 0.78 + 0.14 * weave + 0.12 * (value_noise(rng, size, 8, octaves=3) - 0.5)
    return _to_u8(_tint(gray, color))


def countertop(rng: np.random.Generator, size: int = 256) -> np.ndarray:
    """Speckled stone (granite-like) worktop."""
    base = value_noise(rng, size, 16, octaves=3)
    dots = rng.random((size, size))
    gray = 0.55 + 0.25 * base
    gray = np.where(dots < 0.08, 0.2, np.where(dots > 0.95, 0.95, gray))
    return _to_u8(_tint(gray, (200, 195, 185)))


def book_spines(rng: np.random.Generator, width: int = 256, height: int = 512, rows: int = 5) -> np.ndarray:
    """Front of a filled bookcase: ``rows`` shelves of books of random width, height and colour.

    Not tileable: maps onto the whole front of one bookshelf (u right, v up).
    """
    img = np.full((height, width, 3), 40.0)
    row_h = height // rows
    palette = np.array(
        [[150, 30, 30], [30, 60, 130], [40, 110, 60], [200, 170, 60], [90, 50, 30], [230, 225, 210], [20, 20, 25], [120, 60, 120], [210, 100, 40]],
        dtype=float,
    )
    for r in range(rows):
        bottom = (r + 1) * row_h - 6
        x = 4
        while x < width - 8:
            w = int(rng.integers(6, 18))
            h = int(rng.integers(int(row_h * 0.55), row_h - 8))
            c = palette[rng.integers(len(palette))] * rng.uniform(0.75, 1.1)
            x1 = min(x + w, width - 4)
            img[bottom - h : bottom, x:x1] = c
            # title band and lettering ticks
            band = bottom - h + int(h * rng.uniform(0.2, 0.6))
            img[band : band + 4, x + 1 : x1 - 1] = 255 - c * 0.6
            img[bottom - h : bottom, x] *= 0.6
            x = x1 + int(rng.integers(0, 3))
        img[bottom : (r + 1) * row_h] = (110, 80, 50)  # shelf board edge
    return _to_u8(img)


def rug(rng: np.random.Generator, size: int = 256, colors=((150, 40, 40), (220, 200, 160), (40, 50, 90))) -> np.ndarray:
    """A patterned rug (not tiled: maps onto the whole rug): border, medallions, pile noise."""
    y, x = np.mgrid[0:size, 0:size] / size
    c = [np.asarray(v, dtype=float) for v in colors]
    img = np.empty((size, size, 3))
    img[:] = c[0]
    d = np.minimum(np.minimum(x, 1 - x), np.minimum(y, 1 - y))
    img[(d > 0.05) & (d < 0.1)] = c[1]
    k = int(rng.integers(3, 6))
    pattern = (np.sin(2 * np.pi * k * x) * np.sin(2 * np.pi * k * y)) > 0.3
    img[(d > 0.15) & pattern] = c[2]
    diamond = np.abs(x - 0.5) + np.abs(y - 0.5) < 0.18
    img[diamond] = c[1]
    img *= (0.85 + 0.3 * rng.random((size, size)))[..., None]
    return _to_u8(img)


def screen(rng: np.random.Generator, width: int = 256, height: int = 160) -> np.ndarray:
    """A computer screen showing windows with text lines (not tiled)."""
    img = np.empty((height, width, 3))
    img[:] = rng.integers(30, 90, 3)
    for _ in range(int(rng.integers(2, 4))):
        x0, y0 = int(rng.integers(0, width // 2)), int(rng.integers(0, height // 2))
        x1, y1 = int(rng.integers(x0 + 40, width)), int(rng.integers(y0 + 30, height))
        img[y0:y1, x0:x1] = 235
        img[y0 : y0 + 8, x0:x1] = rng.integers(40, 200, 3)
        for ty in range(y0 + 12, y1 - 4, 6):
            length = int(rng.integers(10, max(11, x1 - x0 - 8)))
            img[ty : ty + 2, x0 + 4 : x0 + 4 + length] = 60
    return _to_u8(img)


def abstract_art(rng: np.random.Generator, width: int = 256, height: int = 320) -> np.ndarray:
    """A modern-art poster: overlapping coloured rectangles and discs (not tiled)."""
    img = np.empty((height, width, 3))
    img[:] = rng.integers(180, 250, 3)
    y, x = np.mgrid[0:height, 0:width]
    for _ in range(int(rng.integers(6, 12))):
        col = rng.integers(0, 255, 3)
        if rng.random() < 0.5:
            x0, y0 = int(rng.integers(0, width)), int(rng.integers(0, height))
            img[y0 : y0 + int(rng.integers(20, 120)), x0 : x0 + int(rng.integers(20, 120))] = col
        else:
            cx, cy, r = rng.integers(0, width), rng.integers(0, height), rng.integers(10, 70)
            img[(x - cx) ** 2 + (y - cy) ** 2 < r * r] = col
    return _to_u8(img)


def foliage(rng: np.random.Generator, size: int = 128) -> np.ndarray:
    """Leafy plant texture (tileable): green blotches; uses the bundled grass photo when present."""
    grass = bundled_photo("grass", 128)
    gray = grass[..., 0] / 255.0 if grass is not None else value_noise(rng, size, 16, octaves=3)
    gray = _resize(_to_u8(gray * 255)[..., None].repeat(3, axis=2), size, size)[..., 0] / 255.0
    return _to_u8(_tint(0.4 + 0.8 * gray, (60, 120, 50)))


def solid(rng: np.random.Generator, color, size: int = 8) -> np.ndarray:
    """A flat colour image (for parts that must carry a texture)."""
    return np.broadcast_to(np.asarray(color, dtype=np.uint8), (size, size, 3)).copy()


# ----------------------------------------------------------------------------------------------
# photos


def bundled_photo(name: str, max_size: int = 512) -> np.ndarray | None:
    """A photo shipped inside scikit-image as (H, W, 3) uint8 RGB, longest side <= ``max_size``.

    Returns None when the file is not in the installed package (nothing is downloaded).
    """
    from PIL import Image

    fname = BUNDLED_PHOTOS.get(name)
    if fname is None:
        raise KeyError(f"unknown bundled photo {name!r}")
    try:
        ref = resources.files("skimage.data") / fname
        with resources.as_file(ref) as p, Image.open(p) as im:
            im = im.convert("RGB")
            scale = max_size / max(im.size)
            if scale < 1:
                im = im.resize((max(1, round(im.size[0] * scale)), max(1, round(im.size[1] * scale))), Image.BILINEAR)
            return np.asarray(im, dtype=np.uint8).copy()
    except (ModuleNotFoundError, FileNotFoundError, OSError) as err:
        log.debug("bundled photo %s unavailable (%s); using a procedural picture", name, err)
        return None


def framed_photo(rng: np.random.Generator, name: str, max_size: int = 384, mat: int = 12) -> np.ndarray:
    """A bundled photo with a white passe-partout border (procedural art if the photo is missing)."""
    photo = bundled_photo(name, max_size)
    if photo is None:
        photo = abstract_art(rng, max_size * 3 // 4, max_size)
    h, w = photo.shape[:2]
    out = np.full((h + 2 * mat, w + 2 * mat, 3), 245, dtype=np.uint8)
    out[mat : mat + h, mat : mat + w] = photo
    return out


def photo(rng: np.random.Generator, name: str, max_size: int = 256) -> np.ndarray:
    """A bundled photo without border (procedural art if the photo is missing)."""
    img = bundled_photo(name, max_size)
    return img if img is not None else abstract_art(rng, max_size, max_size * 3 // 4)
