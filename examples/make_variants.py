"""Regenerate the README's images of the variants and options: ``examples/variant_*.png``.

One group of images per option (tileable output, ``make_tileable``, walk mode, exclusions,
the luminance error, random discarding), each a row of panels of the README's "Variants and
options" table. Deterministic: fixed seeds, the ``fft`` backend (every backend gives the same
bytes anyway). Run from the repository root::

    .venv/bin/python examples/make_variants.py

It prints every image written with its size and the figures quoted in the README.
"""

from __future__ import annotations

import colorsys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

import quilting
from quilting.core.options import Tileable
from quilting.core.stats import ownership

HERE = Path(__file__).resolve().parent
DATA = HERE.parent / "tests" / "data"
BACKEND = "fft"
CUT_COLOR = (255, 0, 0)
TICK = 6  # length of the marks at the joins

Image = NDArray[Any]


def texture(name: str) -> Image:
    """``examples/<name>.png`` as it is (uint8, gray or RGB)."""
    image: Image = quilting.read_image(HERE / f"{name}.png")
    return image


def save(name: str, image: Image, **metadata: Any) -> None:
    """Write ``examples/variant_<name>.png`` and say how big it is."""
    path = HERE / f"variant_{name}.png"
    quilting.write_image(path, image, metadata=metadata or None)
    print(
        f"  {path.relative_to(HERE.parent)}  {image.shape[1]}x{image.shape[0]}  "
        f"{path.stat().st_size / 1024:.0f} KiB"
    )


def tiled(image: Image) -> Image:
    """``image`` repeated 2 x 2, as RGB, red ticks on the borders where the copies meet."""
    reps = (2, 2) + (1,) * (image.ndim - 2)
    out = as_rgb(np.tile(image, reps))
    y, x = image.shape[:2]  # the middle lines, where the copies meet
    out[y - 1 : y + 1, :TICK] = out[y - 1 : y + 1, -TICK:] = CUT_COLOR
    out[:TICK, x - 1 : x + 1] = out[-TICK:, x - 1 : x + 1] = CUT_COLOR
    return out


def as_rgb(image: Image) -> Image:
    """uint8 (H, W, 3) for drawing over."""
    rgb: Image = image if image.ndim == 3 else np.repeat(image[..., None], 3, axis=2)
    return rgb[..., :3].copy()


# --- tileable="both" ------------------------------------------------------------------------


def tileable() -> None:
    """Gravel, 128x128, block 32: the plain result and the tileable one, each repeated 2 x 2."""
    gravel = texture("gravel")
    options: dict[str, Any] = {"block": 32, "seed": 3}
    cases: tuple[tuple[str, Tileable | None], ...] = (("plain", None), ("both", "both"))
    for name, tile in cases:
        result = quilting.synthesize(gravel, (128, 128), tileable=tile, backend=BACKEND, **options)
        save(f"tileable_{name}", tiled(result.image), tileable=tile, **options)


# --- make_tileable --------------------------------------------------------------------------


def photo() -> Image:
    """The top-left 128x128 of the grass photo (tests/data/grass.png)."""
    grass: Image = quilting.read_image(DATA / "grass.png")[:128, :128]
    return grass


def make_tileable() -> None:
    """A photo repeated 2 x 2 before and after ``quilting.make_tileable``, and its four cuts."""
    image, name = photo(), "grass"
    made = quilting.make_tileable(image, axes="both")
    save("make_tileable_before", tiled(image), texture=name)
    save("make_tileable_after", tiled(made.image), texture=name, axes="both")
    # Where the four cuts run (left, right, top, bottom), on one copy magnified 2x.
    shown = as_rgb(made.image)
    for k in range(2):
        shown[np.arange(shown.shape[0]), made.seam_cols[k]] = CUT_COLOR
        shown[made.seam_rows[k], np.arange(shown.shape[1])] = CUT_COLOR
    save("make_tileable_cuts", shown.repeat(2, axis=0).repeat(2, axis=1), texture=name)


# --- mode="walk" ----------------------------------------------------------------------------


def walk() -> None:
    """Gravel, 192x192: random blocks, and random blocks joined by the walk cut, with its seams."""
    gravel = texture("gravel")
    options: dict[str, Any] = {"block": 48, "seed": 1}
    shown = quilting.synthesize(gravel, (192, 192), mode="random", backend=BACKEND, **options)
    save("walk_random", shown.image, mode="random", **options)
    result = quilting.synthesize(gravel, (192, 192), mode="walk", backend=BACKEND, **options)
    save("walk", result.image, mode="walk", **options)
    save("walk_seams", result.seam_overlay(), mode="walk", **options)
    print(
        f"    seam error: random {shown.stats.seam_error_mean:.4f}, "
        f"walk {result.stats.seam_error_mean:.4f}"
    )


# --- exclude_colors and source_mask ---------------------------------------------------------

#: Every channel 60..255: anything brighter than the faint background stars.
BRIGHT = ((60, 60, 60), (255, 255, 255))


def orange_galaxy_mask(image: Image) -> Image:
    """uint8 mask of the texture's size: black around its large reddish objects, else white.

    Objects are the connected regions of the blurred brightness above 30; large means 60
    pixels or more, reddish a mean red above 1.2 times the mean blue; each is widened by 6
    pixels.
    """
    pixels = image.astype(np.float64)
    glow = ndimage.gaussian_filter(pixels.mean(axis=2), 3.0) > 30
    labels, count = ndimage.label(glow)
    index = np.arange(1, count + 1)
    sizes = ndimage.sum_labels(np.ones(glow.shape), labels, index)
    red = np.asarray(ndimage.mean(pixels[..., 0], labels, index))
    blue = np.asarray(ndimage.mean(pixels[..., 2], labels, index))
    chosen = index[(sizes >= 60) & (red > 1.2 * blue)]
    black = ndimage.binary_dilation(np.isin(labels, chosen), iterations=6)
    mask: Image = np.where(black, 0, 255).astype(np.uint8)
    return mask


def exclusion() -> None:
    """Hubble, 192x192: all of it, without the bright objects, without the orange galaxies."""
    hubble = texture("hubble")
    options: dict[str, Any] = {"block": 32, "seed": 5}
    size = (192, 192)
    plain = quilting.synthesize(hubble, size, backend=BACKEND, **options)
    save("exclude_none", plain.image, **options)
    ranged = quilting.synthesize(hubble, size, exclude_colors=[BRIGHT], backend=BACKEND, **options)
    save("exclude_colors", ranged.image, exclude_colors=[list(map(list, BRIGHT))], **options)
    mask = orange_galaxy_mask(hubble)
    save("exclude_mask", mask)
    masked = quilting.synthesize(hubble, size, source_mask=mask, backend=BACKEND, **options)
    save("exclude_masked", masked.image, source_mask="variant_exclude_mask.png", **options)
    inside = np.all((hubble >= BRIGHT[0]) & (hubble <= BRIGHT[1]), axis=2)
    print(f"    {inside.mean():.1%} of the pixels in the range, {np.mean(mask == 0):.1%} masked")


# --- error="luminance" ----------------------------------------------------------------------


def tinted_gravel() -> Image:
    """Gravel (192x192) tinted by a slowly varying hue: colour changes where brightness does not.

    The hue is a Gaussian-blurred noise field (sigma 24, wrapped) turned into ranks, so that
    every hue is as common as any other; saturation 0.7; the value is the gravel's brightness.
    """
    gravel = texture("gravel")[:192, :192].astype(np.float64) / 255
    noise = np.random.default_rng(0).standard_normal(gravel.shape)
    field = ndimage.gaussian_filter(noise, 24.0, mode="wrap")
    hue = (np.argsort(np.argsort(field, axis=None)).reshape(field.shape) + 0.5) / field.size
    to_rgb: Callable[..., tuple[float, float, float]] = np.vectorize(
        colorsys.hsv_to_rgb, otypes=[float, float, float]
    )
    rgb = np.stack(to_rgb(hue, 0.7, 0.25 + 0.75 * gravel), axis=2)
    tinted: Image = np.rint(rgb * 255).astype(np.uint8)
    return tinted


def error() -> None:
    """The tinted gravel (192x192), 192x192 out: overlap error on RGB and on luminance only."""
    colourful = tinted_gravel()
    save("error_texture", colourful)
    options: dict[str, Any] = {"block": 32, "seed": 2}
    for kind in ("rgb", "luminance"):
        result = quilting.synthesize(colourful, (192, 192), error=kind, backend=BACKEND, **options)
        save(f"error_{kind}", result.image, error=kind, **options)


# --- discard --------------------------------------------------------------------------------


def largest_copy(result: quilting.Result) -> NDArray[np.bool_]:
    """Output pixels in the largest region copied verbatim from one place of the texture."""
    own = ownership(result.layout)
    owner, offsets = own.owner, own.offsets
    blocks = offsets.shape[0]
    pairs = []
    for a, b in ((owner[:, :-1], owner[:, 1:]), (owner[:-1, :], owner[1:, :])):
        boundary = a != b
        pa, pb = a[boundary], b[boundary]
        same = np.all(offsets[pa] == offsets[pb], axis=1)
        pairs.append(np.stack([pa[same], pb[same]], axis=1))
    edges = np.concatenate(pairs)
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(blocks, blocks))
    _, component = connected_components(graph, directed=False)
    pixels = np.bincount(component[owner.ravel()], minlength=component.max() + 1)
    region: NDArray[np.bool_] = component[owner] == pixels.argmax()
    return region


def discard() -> None:
    """Brick, 256x256, the paper's bare rule: the largest verbatim copy tinted, discard 0..0.9."""
    brick = texture("brick")
    options: dict[str, Any] = {"block": 40, "seed": 1, "min_candidates": 1}
    for p in (0.0, 0.5, 0.9):
        result = quilting.synthesize(brick, (256, 256), discard=p, backend=BACKEND, **options)
        shown = as_rgb(result.image).astype(np.float64)
        region = largest_copy(result)
        if abs(region.sum() / brick.size - result.stats.largest_copy) > 1e-9:
            print(
                "    warning: the tinted region is not the one Result.stats.largest_copy measures"
            )
        shown[region] = 0.55 * shown[region] + 0.45 * np.array([255.0, 40.0, 0.0])
        name = f"discard_{int(p * 10):02d}"
        save(name, np.rint(shown).astype(np.uint8), discard=p, **options)
        print(f"    discard={p}: largest copy {result.stats.largest_copy:.1%} of the texture")


def main() -> None:
    for make in (tileable, make_tileable, walk, exclusion, error, discard):
        print(f"{make.__name__}:")
        make()
    total = sum(p.stat().st_size for p in HERE.glob("variant_*.png"))
    print(f"total: {total / 1024:.0f} KiB")


if __name__ == "__main__":
    main()
