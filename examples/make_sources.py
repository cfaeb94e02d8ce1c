"""Make the pictures of docs/sources.md (several examples, transforms, Wang tiles) in docs/images.

Written (each deterministic: seed 1, the ``fft`` backend):

* ``sources_sample.png``: the 128x128 sample of the next two pictures, a crop of the Hubble
  deep field (``tests/data/hubble.png``, rows 64-191, columns 96-223) with its elongated
  galaxies all lying one way, shown at 2x.
* ``sources_none.png`` and ``sources_all.png``: 448x448 quilted from that sample with
  ``transforms='none'`` (every galaxy copied as it lies) and ``'all'`` (its rotations and
  mirrors too).
* ``sources_three.png``: three 128x128 crops of gravel (``tests/data/gravel.png``) stacked on
  the left, then 400x400 quilted from the first crop alone and from the three.
* ``wang_atlas.png``: the 16 Wang tiles (``colors=2``, ``tile=256``) made from
  ``examples/stones.png``, as ``WangTiles.atlas()`` lays them out, at half size.
* ``wang_edges.png``: the same atlas with 6 px between the tiles, every pixel tinted by the
  edge colour of the diamond it shows and a bar of that colour along each edge: north and
  south colours red (0) and blue (1), west and east colours green (0) and amber (1). Two
  tiles may touch where their bars have one colour; across that edge both show that diamond.
* ``wang_layout.png``: a 6x6 arrangement of the set (``arrange(6, 6, seed=1)``, 1536x1536),
  at a third of its size, small red ticks on the border where the tiles meet.

``examples/stones.png`` (256x256 RGB, Voronoi cobbles with rounded edges, no light direction)
is written first when it is missing: it is ``quality_textures.procedural("stones")`` of
``benchmarks/`` (generated from a fixed seed; no rights reserved).

Run from the repository root::

    .venv/bin/python examples/make_sources.py

It prints every picture written with its size in pixels and KiB and what made it.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from PIL import Image as PILImage

import quilting

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
DATA = ROOT / "tests" / "data"
OUT = ROOT / "docs" / "images"
STONES = HERE / "stones.png"
BACKEND = "fft"
SEED = 1
GAP = 8
TICK = (255, 0, 0)
#: Edge colours: (north/south colour 0, 1), (west/east colour 0, 1).
HORIZONTAL = ((220, 40, 40), (40, 90, 230))
VERTICAL = ((40, 170, 60), (240, 170, 20))
#: Top-left corners of the three 128x128 crops of ``sources_three.png``.
CROPS = ((0, 0), (0, 128), (128, 64))

Image = NDArray[Any]


def rgb(image: Image) -> Image:
    """uint8 (H, W, 3): gray repeated, alpha dropped."""
    out: Image = image if image.ndim == 3 else np.repeat(image[..., None], 3, axis=2)
    return np.ascontiguousarray(out[..., :3])


def scaled(image: Image, factor: float) -> Image:
    """``image`` resized by ``factor``: nearest when enlarging (pixels stay visible), else
    Lanczos."""
    if factor == 1:
        return image
    pil = PILImage.fromarray(rgb(image))
    size = (round(pil.width * factor), round(pil.height * factor))
    kind = PILImage.Resampling.NEAREST if factor > 1 else PILImage.Resampling.LANCZOS
    return np.asarray(pil.resize(size, kind))


def save(name: str, image: Image, note: str) -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    path = OUT / name
    PILImage.fromarray(rgb(image)).save(path, optimize=True)
    size = path.stat().st_size / 1024
    print(f"  {path.relative_to(ROOT)}  {image.shape[1]}x{image.shape[0]}  {size:.0f} KiB  {note}")


def stones() -> Image:
    """``examples/stones.png``, written from the benchmarks' generator when missing."""
    if not STONES.is_file():
        sys.path.insert(0, str(ROOT / "benchmarks"))
        import quality_textures

        quilting.write_image(STONES, quality_textures.procedural("stones", cache=False))
        print(f"  {STONES.relative_to(ROOT)} written (quality_textures.procedural('stones'))")
    image: Image = quilting.read_image(STONES)
    return image


def timed(texture: Any, side: int, **options: Any) -> tuple[Image, str]:
    start = time.perf_counter()
    result = quilting.synthesize(texture, (side, side), seed=SEED, backend=BACKEND, **options)
    return result.image, f"{time.perf_counter() - start:.2f} s"


def transforms() -> None:
    sample = np.ascontiguousarray(quilting.read_image(DATA / "hubble.png")[64:192, 96:224])
    save("sources_sample.png", scaled(sample, 2), "hubble rows 64-191, columns 96-223, 2x")
    for preset in ("none", "all"):
        image, note = timed(sample, 448, transforms=preset)
        save(f"sources_{preset}.png", image, f"transforms='{preset}', {note}")


def three() -> None:
    gravel = quilting.read_image(DATA / "gravel.png")
    crops = [np.ascontiguousarray(gravel[y : y + 128, x : x + 128]) for y, x in CROPS]
    side = 3 * 128 + 2 * GAP
    column = np.full((side, 128, 3), 255, dtype=np.uint8)
    for k, part in enumerate(crops):
        column[k * (128 + GAP) : k * (128 + GAP) + 128] = rgb(part)
    one, one_note = timed(crops[0], side)
    many, many_note = timed(crops, side)
    gap = np.full((side, 2 * GAP, 3), 255, dtype=np.uint8)
    thin = gap[:, :GAP]
    picture = np.concatenate([column, gap, rgb(one), thin, rgb(many)], axis=1)
    save("sources_three.png", picture, f"one example {one_note}; three {many_note}")


def edges_picture(tiles: quilting.WangTiles, factor: float) -> Image:
    """The atlas with the tiles apart, tinted by their diamonds' edge colours, edge bars."""
    t = round(tiles.tile * factor)
    rows, cols = tiles.grid
    gap, bar = 6, 5
    out = np.full((rows * t + (rows - 1) * gap, cols * t + (cols - 1) * gap, 3), 255, np.uint8)
    for k in range(len(tiles.tiles)):
        n, e, s, w = (int(c) for c in tiles.edges[k])
        # Which diamond each pixel shows (0 north, 1 east, 2 south, 3 west) -> its colour.
        tint = np.array([HORIZONTAL[n], VERTICAL[e], HORIZONTAL[s], VERTICAL[w]], np.float64)
        image = rgb(tiles.tiles[k]).astype(np.float64)
        coloured = 0.6 * image + 0.4 * tint[tiles.labels[k]]
        small = scaled(np.clip(coloured, 0, 255).astype(np.uint8), factor).copy()
        small[:bar, bar:-bar] = HORIZONTAL[n]
        small[-bar:, bar:-bar] = HORIZONTAL[s]
        small[bar:-bar, :bar] = VERTICAL[w]
        small[bar:-bar, -bar:] = VERTICAL[e]
        y, x = (k // cols) * (t + gap), (k % cols) * (t + gap)
        out[y : y + t, x : x + t] = small
    return out


def ticked(image: Image, count: int, length: int = 8) -> Image:
    """Red ticks on the border of ``image`` where ``count`` x ``count`` tiles meet."""
    out = rgb(image).copy()
    for k in range(1, count):
        y, x = round(k * out.shape[0] / count), round(k * out.shape[1] / count)
        out[y - 1 : y + 1, :length] = out[y - 1 : y + 1, -length:] = TICK
        out[:length, x - 1 : x + 1] = out[-length:, x - 1 : x + 1] = TICK
    return out


def wang() -> None:
    texture = stones()
    start = time.perf_counter()
    tiles = quilting.wang_tiles(texture, colors=2, tile=256, seed=SEED, backend=BACKEND)
    note = f"wang_tiles {time.perf_counter() - start:.2f} s (first call)"
    save("wang_atlas.png", scaled(tiles.atlas(), 0.5), f"16 tiles of 256², half size; {note}")
    save("wang_edges.png", edges_picture(tiles, 0.5), "edge colours and diamonds, half size")
    arrangement = tiles.arrange(6, 6, seed=SEED)
    layout = scaled(tiles.render(arrangement), 1 / 3)
    save("wang_layout.png", ticked(layout, 6), "6x6 arrangement, 1/3 size")


def main() -> int:
    print(f"writing {OUT.relative_to(ROOT)}/:")
    for make in (transforms, three, wang):
        make()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
