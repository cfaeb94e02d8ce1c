"""Make the before/after pictures of filling, extending and make_tileable: ``docs/images/``.

Each picture is a row of panels, 8 px of white between them; in a "before" panel the pixels to
synthesize are painted magenta. Written:

* ``fill_cat.png``: the cat photograph (``examples/cat.png``, 451x300) with an ellipse (48x60
  px) of the blurred background right of the cat's eye removed; filled with a block of 16 px
  (middle) and with the default 32 px (right). The background strip beside the cat is only
  about 90 px wide, so few whole 32 px blocks of it exist, and the default picks blocks with
  fur in them; 16 px blocks keep to the background. The photo's right third (rows 40-279)
  is shown, at 2x.
* ``fill_gravel.png``: ``tests/data/gravel.png`` (256²) with an irregular hole of 20 % (a
  ragged blob), filled with the defaults.
* ``fill_order.png``: the same hole filled with 16 px blocks, each pixel coloured by the
  round of the onion peel whose block last wrote it (red first, yellow last), and the result.
* ``fill_wood.png``: ``tests/data/wood.png`` (136², RGB) with a 48x40 hole across its grain,
  filled with the defaults; shown at 2x.
* ``extend_wood.png``: the wood grown by 64 px on each side (136² to 264²) with
  ``quilting.extend``, the defaults.
* ``tile_brick.png``: ``tests/data/brick.png`` made tileable by ``method="cut"`` and by
  ``method="fill"``, each shown repeated 2x2 (red ticks at the borders where the copies
  meet), at 3/4 size.

Deterministic: fixed seeds, the ``fft`` backend (every backend gives the same bytes). Run from
the repository root::

    .venv/bin/python examples/fill_pictures.py

It prints every picture written with its size in pixels and KiB and the fill's time.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from PIL import Image as PILImage
from scipy import ndimage

import quilting

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
DATA = ROOT / "tests" / "data"
OUT = ROOT / "docs" / "images"
BACKEND = "fft"
SEED = 1
HOLE = (255, 0, 255)
TICK = (255, 0, 0)
GAP = 8

Image = NDArray[Any]


def load(path: Path) -> Image:
    image: Image = quilting.read_image(path)
    return image


def rgb(image: Image) -> Image:
    """uint8 (H, W, 3) for drawing over: gray repeated, alpha dropped."""
    out: Image = image if image.ndim == 3 else np.repeat(image[..., None], 3, axis=2)
    return np.ascontiguousarray(out[..., :3])


def before(image: Image, hole: NDArray[np.bool_]) -> Image:
    """``image`` with ``hole`` painted magenta."""
    out = rgb(image).copy()
    out[hole] = HOLE
    return out


def scaled(image: Image, factor: float) -> Image:
    """``image`` resized by ``factor``: nearest when enlarging (pixels stay visible), else
    bicubic."""
    if factor == 1:
        return image
    pil = PILImage.fromarray(image)
    size = (round(pil.width * factor), round(pil.height * factor))
    kind = PILImage.Resampling.NEAREST if factor > 1 else PILImage.Resampling.BICUBIC
    return np.asarray(pil.resize(size, kind))


def row(*panels: Image, factor: float = 1) -> Image:
    """RGB panels of one height side by side, ``GAP`` white pixels between them."""
    shown = [scaled(rgb(p), factor) for p in panels]
    gap = np.full((shown[0].shape[0], GAP, 3), 255, dtype=np.uint8)
    parts: list[Image] = []
    for k, panel in enumerate(shown):
        parts += [gap, panel] if k else [panel]
    return np.concatenate(parts, axis=1)


def tiled(image: Image) -> Image:
    """``image`` repeated 2x2 as RGB, red ticks on the borders where the copies meet."""
    out = np.tile(rgb(image), (2, 2, 1))
    y, x, t = image.shape[0], image.shape[1], 6
    out[y - 1 : y + 1, :t] = out[y - 1 : y + 1, -t:] = TICK
    out[:t, x - 1 : x + 1] = out[-t:, x - 1 : x + 1] = TICK
    return out


def save(name: str, image: Image, note: str) -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    path = OUT / name
    quilting.write_image(path, image)
    size = path.stat().st_size / 1024
    print(f"  {path.relative_to(ROOT)}  {image.shape[1]}x{image.shape[0]}  {size:.0f} KiB  {note}")


def timed_fill(image: Image, hole: NDArray[np.bool_], **options: Any) -> tuple[Image, str]:
    start = time.perf_counter()
    done = quilting.fill(image, hole, seed=SEED, backend=BACKEND, **options)
    note = f"fill {time.perf_counter() - start:.2f} s, {done.blocks} blocks"
    return done.image, note


def blob(shape: tuple[int, int], fraction: float, seed: int = 3) -> NDArray[np.bool_]:
    """A ragged centred hole of about ``fraction`` of the image: distance from the centre plus
    smoothed noise, thresholded, its largest piece with its holes closed."""
    rng = np.random.default_rng(seed)
    height, width = shape
    y, x = np.mgrid[0:height, 0:width]
    distance = np.hypot(y / height - 0.5, x / width - 0.5)
    noise = ndimage.gaussian_filter(rng.standard_normal(shape), min(shape) / 24)
    field = distance + noise / noise.std() * 0.08
    labels, _ = ndimage.label(field <= np.quantile(field, fraction))
    sizes = np.bincount(labels.ravel())[1:]
    mask: NDArray[np.bool_] = ndimage.binary_fill_holes(labels == 1 + int(np.argmax(sizes)))
    return mask


def ellipse(
    shape: tuple[int, int], centre: tuple[int, int], radii: tuple[int, int]
) -> NDArray[np.bool_]:
    y, x = np.mgrid[0 : shape[0], 0 : shape[1]]
    inside: NDArray[np.bool_] = ((y - centre[0]) / radii[0]) ** 2 + (
        (x - centre[1]) / radii[1]
    ) ** 2 <= 1
    return inside


def cat() -> None:
    photo = load(HERE / "cat.png")
    hole = ellipse(photo.shape[:2], (160, 420), (30, 24))
    small, note = timed_fill(photo, hole, block=16)
    default, default_note = timed_fill(photo, hole)
    view = np.s_[40:280, 300:]
    picture = row(before(photo, hole)[view], small[view], default[view], factor=2)
    save("fill_cat.png", picture, f"block 16: {note}; block 32: {default_note}")


def gravel() -> None:
    image = load(DATA / "gravel.png")
    hole = blob(image.shape[:2], 0.20)
    filled, note = timed_fill(image, hole)
    save("fill_gravel.png", row(before(image, hole), filled), f"{note}, hole {hole.mean():.1%}")


def order() -> None:
    """The fill order on gravel's hole, with 16 px blocks (more rounds than the default's two):
    each pixel coloured by the onion-peel round whose block last wrote it (red first, yellow
    last), beside the result."""
    image = load(DATA / "gravel.png")
    hole = blob(image.shape[:2], 0.20)
    done = quilting.fill(image, hole, block=16, seed=SEED, backend=BACKEND)
    assert done.rounds is not None
    rounds = done.rounds.astype(np.float64)
    last = max(1.0, float(rounds.max()))
    shade = rgb(image).astype(np.float64) * 0.35
    written = rounds >= 0
    t = rounds[written] / last
    shade[written] = np.stack([200 + 55 * t, 40 + 200 * t, 30 + 20 * t], axis=-1)
    save(
        "fill_order.png",
        row(shade.astype(np.uint8), done.image),
        f"{int(last) + 1} rounds, {done.blocks} blocks",
    )


def wood() -> None:
    image = load(DATA / "wood.png")
    hole = np.zeros(image.shape[:2], dtype=bool)
    hole[48:88, 44:92] = True
    filled, note = timed_fill(image, hole)
    save("fill_wood.png", row(before(image, hole), filled, factor=2), note)


def extend_wood() -> None:
    image = load(DATA / "wood.png")
    pad = 64
    start = time.perf_counter()
    done = quilting.extend(
        image, top=pad, bottom=pad, left=pad, right=pad, seed=SEED, backend=BACKEND
    )
    note = f"extend {time.perf_counter() - start:.2f} s, {done.blocks} blocks"
    canvas = np.zeros_like(done.image)
    canvas[pad:-pad, pad:-pad] = image
    save("extend_wood.png", row(before(canvas, done.filled), done.image), note)


def brick() -> None:
    image = load(DATA / "brick.png")
    panels = []
    notes = []
    for method in ("cut", "fill"):
        start = time.perf_counter()
        made = quilting.make_tileable(image, method=method, seed=SEED)
        notes.append(f"{method} {1000 * (time.perf_counter() - start):.0f} ms")
        panels.append(tiled(made.image))
    save("tile_brick.png", row(*panels, factor=0.75), ", ".join(notes))


def main() -> int:
    # A first small fill loads the compiled kernels, so the times printed are the fills' own.
    warm = np.zeros((64, 64), dtype=np.uint8)
    warm[::2] = 255
    quilting.fill(warm, np.pad(np.ones((16, 16), dtype=bool), 24), block=8, backend=BACKEND)
    print(f"writing {OUT.relative_to(ROOT)}/:")
    for make in (cat, gravel, order, wood, extend_wood, brick):
        make()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
