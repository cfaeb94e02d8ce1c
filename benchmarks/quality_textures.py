"""Textures for the quality benchmark: procedural ones made here, and the photos in the repository.

The procedural textures are generated on demand from fixed seeds with numpy and scipy only
(no image files are shipped, so there is no binary in the repository and no licence to
track). Each is 256x256 or 192x192, uint8, gray ``(H, W)`` or RGB ``(H, W, 3)``, and the same
bytes on every call. They were chosen to cover what photographs of textures do and the test
photos do not:

============  ====  =====  ==============================================================
name          side  kind   character
============  ====  =====  ==============================================================
stones        256   RGB    Voronoi cobbles: rounded cells of varied colour, dark joints
wood_rings    256   RGB    growth rings around an off-image centre, with fine grain
bark          256   gray   ridged, vertically stretched noise (deep furrows)
marble        256   RGB    veins from a sine distorted by turbulence
bricks        256   RGB    running-bond lattice, jittered mortar, per-brick colour
fabric        192   RGB    plain weave of warp and weft threads with thickness jitter
leopard       256   RGB    rosettes (dark rings around cell centres) on ochre
ripples       256   gray   asymmetric sand ripples, bent by noise, with grain
clouds        256   RGB    fractal (fBm) cloud on blue
cracked       256   RGB    dry mud: thin dark cracks between tan plates
pebbles       256   RGB    shaded pebbles scattered on sand
drift         256   gray   fine gravel-like noise under a left-to-right brightness ramp
furrows       192   gray   strongly oriented diagonal grain (streaks at 30 degrees)
============  ====  =====  ==============================================================

``drift`` imitates the brightness gradient of many photographed textures (wood, bark under
uneven light); ``furrows`` and ``bark`` are strongly oriented. The generators are periodic
where that came free (spectral noise, wrapped Voronoi) but nothing relies on it.

:func:`procedural` returns one texture (cached as ``.npy`` under ``benchmarks/.cache/``,
which git ignores; pass ``cache=False`` to skip the cache), :func:`procedural_names` the names,
:func:`photos` the photographic textures of the repository (``tests/data`` and ``examples``,
targets and outputs left out; see its docstring).

Write them out as PNG to look at them::

    .venv/bin/python benchmarks/quality_textures.py --png /tmp/textures
"""

from __future__ import annotations

import argparse
import hashlib
from collections.abc import Callable
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage, spatial

ROOT = Path(__file__).resolve().parents[1]
CACHE = Path(__file__).resolve().parent / ".cache" / "quality_textures"
#: Bump when a generator changes, so that stale cached textures are not read.
VERSION = 1

Float = NDArray[np.float64]
Texture = NDArray[np.uint8]


# --- building blocks -------------------------------------------------------------------------


def _spectral_noise(rng: np.random.Generator, side: int, beta: float, low: float = 1.0) -> Float:
    """Periodic Gaussian noise with a ``1 / f**beta`` amplitude spectrum, zero mean, unit std.

    ``low`` (in cycles per image) flattens the spectrum below it, so that the largest
    features are about ``side / low`` pixels.
    """
    white = rng.standard_normal((side, side))
    fy = np.fft.fftfreq(side)[:, None] * side
    fx = np.fft.rfftfreq(side)[None, :] * side
    f = np.maximum(np.hypot(fy, fx), low)
    field: Float = np.fft.irfft2(np.fft.rfft2(white) / f**beta, s=(side, side))
    return _float((field - field.mean()) / field.std())


def _anisotropic_noise(
    rng: np.random.Generator, side: int, sigma: tuple[float, float], angle: float = 0.0
) -> Float:
    """White noise blurred by an oriented Gaussian (``sigma`` = (across, along) the grain),
    then rotated by ``angle`` degrees; zero mean, unit std."""
    pad = side // 2 if angle else 0
    white = rng.standard_normal((side + 2 * pad, side + 2 * pad))
    field = ndimage.gaussian_filter(white, sigma=(sigma[1], sigma[0]), mode="wrap")
    if angle:
        field = ndimage.rotate(field, angle, reshape=False, order=1, mode="reflect")
        field = field[pad : pad + side, pad : pad + side]
    return _float((field - field.mean()) / field.std())


def _voronoi(
    rng: np.random.Generator, side: int, cells: int
) -> tuple[Float, Float, NDArray[np.intp], Float]:
    """Periodic Voronoi diagram of ``cells`` random sites on a ``side``-pixel torus.

    Returns
    -------
    f1, f2 : ndarray of float, shape (side, side)
        Distance (pixels) to the nearest and the second nearest site.
    label : ndarray of int, shape (side, side)
        Index of the nearest site (0..cells-1).
    offset : ndarray of float, shape (side, side, 2)
        (dy, dx) from the nearest site to the pixel.
    """
    sites = rng.uniform(0, side, size=(cells, 2))
    shifts = np.array([(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1)], dtype=np.float64)
    tiled = (sites[None, :, :] + side * shifts[:, None, :]).reshape(-1, 2)
    yy, xx = np.mgrid[0:side, 0:side].astype(np.float64)
    pixels = np.stack([yy.ravel(), xx.ravel()], axis=-1)
    dist, index = spatial.cKDTree(tiled).query(pixels, k=2)
    nearest = index[:, 0]
    offset = (pixels - tiled[nearest]).reshape(side, side, 2)
    label = (nearest % cells).reshape(side, side)
    return dist[:, 0].reshape(side, side), dist[:, 1].reshape(side, side), label, offset


def _float(values: object) -> Float:
    """``values`` as a float64 array (a typed view of numpy's results)."""
    return np.asarray(values, dtype=np.float64)


def _normalize(field: Float) -> Float:
    """Linearly onto [0, 1]."""
    lo, hi = float(field.min()), float(field.max())
    return (field - lo) / max(hi - lo, 1e-12)


def _mix(t: Float, low: tuple[float, float, float], high: tuple[float, float, float]) -> Float:
    """RGB image (H, W, 3) going from colour ``low`` at t = 0 to ``high`` at t = 1."""
    lo, hi = np.asarray(low, dtype=np.float64), np.asarray(high, dtype=np.float64)
    return lo + np.clip(t, 0.0, 1.0)[..., None] * (hi - lo)


def _to_uint8(image: Float) -> Texture:
    """Values in [0, 1] (clipped) to uint8."""
    return np.asarray(np.rint(np.clip(image, 0.0, 1.0) * 255.0), dtype=np.uint8)


# --- the textures -----------------------------------------------------------------------------


def _stones(rng: np.random.Generator) -> Float:
    side = 256
    f1, f2, label, _ = _voronoi(rng, side, 60)
    edge = f2 - f1  # 0 on a joint
    joint = np.clip(edge / 5.0, 0.0, 1.0) ** 0.6  # rounded stone edges
    tint = rng.uniform(0.0, 1.0, size=(label.max() + 1, 1))
    base = _mix(tint[label][..., 0], (0.42, 0.38, 0.33), (0.72, 0.66, 0.55))
    shade = 0.85 + 0.15 * _spectral_noise(rng, side, 1.2, 8.0)[..., None]
    grit = 0.04 * _spectral_noise(rng, side, 0.3, 1.0)[..., None]
    mortar = np.array([0.22, 0.21, 0.2])
    return _float(mortar + joint[..., None] * (base * shade - mortar) + grit)


def _wood_rings(rng: np.random.Generator) -> Float:
    side = 256
    yy, xx = np.mgrid[0:side, 0:side].astype(np.float64)
    cy, cx = -180.0, 96.0  # the pith, outside the image: rings cross it as arcs
    r = np.hypot((yy - cy) * 1.0, (xx - cx) * 1.6)
    r += 6.0 * _spectral_noise(rng, side, 2.0, 2.0)
    phase = r / 9.0
    ring = (phase % 1.0) ** 3  # slow growth, then the sharp late-wood edge
    grain = _anisotropic_noise(rng, side, (0.7, 14.0), angle=-20.0)
    t = 0.55 * ring + 0.12 * grain + 0.2
    return _mix(t, (0.55, 0.34, 0.17), (0.86, 0.66, 0.42))


def _bark(rng: np.random.Generator) -> Float:
    side = 256
    n = _anisotropic_noise(rng, side, (4.0, 40.0))
    n += 0.5 * _anisotropic_noise(rng, side, (2.0, 20.0))
    n /= n.std()
    furrow = np.exp(-((n / 0.35) ** 2))  # dark cracks along the zero crossings: vertical
    plate = 0.55 + 0.15 * _anisotropic_noise(rng, side, (1.0, 6.0))
    return plate * (1.0 - 0.85 * furrow) + 0.05 * _spectral_noise(rng, side, 1.5, 4.0)


def _marble(rng: np.random.Generator) -> Float:
    side = 256
    yy, xx = np.mgrid[0:side, 0:side].astype(np.float64)
    turbulence = np.zeros((side, side))
    for octave in range(3):
        turbulence += np.abs(_spectral_noise(rng, side, 2.5, 2.0**octave)) / 2**octave
    vein = np.abs(np.sin(2 * np.pi * (xx + 0.5 * yy) / 110.0 + 1.8 * turbulence))
    t = vein**0.3  # dark veins where the sine crosses zero
    fine = 0.02 * _spectral_noise(rng, side, 0.5, 1.0)
    return _mix(t, (0.35, 0.36, 0.42), (0.92, 0.91, 0.88)) + fine[..., None]


def _bricks(rng: np.random.Generator) -> Float:
    side, height, width = 256, 32, 64
    yy, xx = np.mgrid[0:side, 0:side]
    course = yy // height
    shifted = xx + (course % 2) * (width // 2)
    column = shifted // width
    brick_id = course * (side // width + 1) + column
    n_ids = int(brick_id.max()) + 1
    # mortar: 3..5 pixels, jittered per brick, plus noise along the joint
    half = rng.uniform(1.5, 2.6, size=n_ids)[brick_id]
    jitter = 0.8 * _spectral_noise(rng, side, 1.0, 16.0)
    dy = np.minimum(yy % height, height - yy % height)
    dx = np.minimum(shifted % width, width - shifted % width)
    mortar = np.minimum(dy, dx) < half + jitter
    tint = rng.uniform(0.0, 1.0, size=n_ids)[brick_id]
    base = _mix(tint, (0.45, 0.17, 0.10), (0.72, 0.36, 0.22))
    speckle = 0.06 * _spectral_noise(rng, side, 0.4, 1.0)[..., None]
    colour = base + speckle
    return np.where(mortar[..., None], np.array([0.70, 0.68, 0.62]) + speckle / 2, colour)


def _fabric(rng: np.random.Generator) -> Float:
    side, pitch = 192, 12
    yy, xx = np.mgrid[0:side, 0:side].astype(np.float64)
    thick_x = 1.0 + 0.12 * rng.standard_normal(side // pitch)  # warp (vertical) threads
    thick_y = 1.0 + 0.12 * rng.standard_normal(side // pitch)  # weft (horizontal) threads
    cx = (xx % pitch) / pitch - 0.5
    cy = (yy % pitch) / pitch - 0.5
    ix = (xx // pitch).astype(np.intp)
    iy = (yy // pitch).astype(np.intp)
    warp = np.clip(1.0 - (2 * cx / (0.85 * thick_x[ix])) ** 2, 0.0, 1.0)
    weft = np.clip(1.0 - (2 * cy / (0.85 * thick_y[iy])) ** 2, 0.0, 1.0)
    warp_on_top = (ix + iy) % 2 == 0
    # the thread on top is lit along its length, the one beneath shows where the top one is thin
    top = np.where(warp_on_top, warp * (0.75 + 0.25 * np.cos(np.pi * cy)), 0.0)
    under = np.where(warp_on_top, 0.0, weft * (0.75 + 0.25 * np.cos(np.pi * cx)))
    lum_warp = np.where(warp_on_top, top, 0.35 * warp)
    lum_weft = np.where(warp_on_top, 0.35 * weft, under)
    fuzz = 0.05 * _spectral_noise(rng, side, 0.2, 1.0)
    warp_rgb = _mix(lum_warp, (0.05, 0.07, 0.16), (0.25, 0.35, 0.72))
    weft_rgb = _mix(lum_weft, (0.05, 0.04, 0.03), (0.86, 0.82, 0.70))
    return np.where((lum_warp >= lum_weft)[..., None], warp_rgb, weft_rgb) + fuzz[..., None]


def _leopard(rng: np.random.Generator) -> Float:
    side = 256
    _, _, label, offset = _voronoi(rng, side, 80)
    n = int(label.max()) + 1
    radius = rng.uniform(7.0, 10.0, size=n)[label]
    stretch = rng.uniform(0.75, 1.3, size=n)[label]
    warp = 1.8 * _spectral_noise(rng, side, 2.0, 4.0)
    r = np.hypot(offset[..., 0] * stretch, offset[..., 1] / stretch) + warp
    ring = np.exp(-(((r - radius) / 2.2) ** 2))  # the dark rosette
    inside = r < radius - 1.5
    fur = 0.05 * _anisotropic_noise(rng, side, (0.6, 3.0), angle=70.0)
    ground = _mix(0.5 + fur, (0.70, 0.47, 0.18), (0.90, 0.70, 0.36))
    centre = np.array([0.62, 0.38, 0.14])
    image = np.where(inside[..., None], centre + fur[..., None], ground)
    dark = np.array([0.10, 0.07, 0.05])
    return _float(image + np.clip(ring, 0.0, 1.0)[..., None] * (dark - image))


def _ripples(rng: np.random.Generator) -> Float:
    side = 256
    yy, xx = np.mgrid[0:side, 0:side].astype(np.float64)
    bend = 10.0 * _spectral_noise(rng, side, 2.2, 2.0)
    phase = ((yy + 0.15 * xx + bend) / 21.0) % 1.0
    profile = np.where(phase < 0.7, phase / 0.7, (1.0 - phase) / 0.3)  # gentle up, steep down
    grain = 0.07 * rng.standard_normal((side, side))
    return _float(0.28 + 0.45 * profile + grain)


def _clouds(rng: np.random.Generator) -> Float:
    side = 256
    fbm = _normalize(_spectral_noise(rng, side, 1.7, 2.0))
    t = np.clip((fbm - 0.35) / 0.5, 0.0, 1.0) ** 1.2
    return _mix(t, (0.25, 0.45, 0.80), (0.97, 0.97, 0.98))


def _cracked(rng: np.random.Generator) -> Float:
    side = 256
    f1, f2, label, _ = _voronoi(rng, side, 70)
    wobble = 1.2 * _spectral_noise(rng, side, 1.5, 12.0)
    crack = np.clip((f2 - f1 + wobble) / 2.5, 0.0, 1.0)  # 0 in a crack
    n = int(label.max()) + 1
    tint = rng.uniform(0.0, 1.0, size=n)[label]
    plate = _mix(0.35 + 0.4 * tint, (0.52, 0.40, 0.27), (0.80, 0.68, 0.50))
    # plates curl up: lighter at their edges
    curl = 0.08 * np.clip(1.0 - (f2 - f1) / 14.0, 0.0, 1.0)
    dust = 0.05 * _spectral_noise(rng, side, 0.6, 1.0)
    surface = plate + (curl + dust)[..., None]
    gap = np.array([0.16, 0.11, 0.07])
    return _float(gap + crack[..., None] ** 2 * (surface - gap))


def _pebbles(rng: np.random.Generator) -> Float:
    side = 256
    grain = 0.5 + 0.25 * _spectral_noise(rng, side, 0.5, 1.0)
    sand = _mix(grain, (0.66, 0.58, 0.43), (0.84, 0.76, 0.60))
    image = sand.copy()
    yy, xx = np.mgrid[0:side, 0:side].astype(np.float64)
    for _ in range(70):
        cy, cx = rng.uniform(0, side, size=2)
        ry, rx = rng.uniform(5.0, 13.0, size=2)
        angle = rng.uniform(0, np.pi)
        dy = (yy - cy + side / 2) % side - side / 2  # periodic placement
        dx = (xx - cx + side / 2) % side - side / 2
        u = (dx * np.cos(angle) + dy * np.sin(angle)) / rx
        v = (-dx * np.sin(angle) + dy * np.cos(angle)) / ry
        d = u**2 + v**2
        inside = d < 1.0
        if not inside.any():
            continue
        height = np.sqrt(np.clip(1.0 - d, 0.0, 1.0))
        light = 0.55 + 0.45 * np.clip(height - 0.5 * (u + v) * 0.5, 0.0, 1.0)
        colour = _mix(np.full((side, side), rng.uniform()), (0.30, 0.29, 0.28), (0.70, 0.62, 0.55))
        shadow = (d >= 1.0) & (d < 1.5)
        image[shadow] *= 0.85
        image[inside] = (colour * light[..., None])[inside]
    return image


def _drift(rng: np.random.Generator) -> Float:
    side = 256
    detail = _spectral_noise(rng, side, 0.8, 1.0)
    blobs = _spectral_noise(rng, side, 1.5, 6.0)
    base = 0.5 + 0.15 * detail + 0.1 * blobs
    ramp = np.linspace(0.45, 1.15, side)[None, :]  # uneven light, left to right
    return base * ramp - 0.03


def _furrows(rng: np.random.Generator) -> Float:
    side = 192
    streaks = _anisotropic_noise(rng, side, (1.2, 25.0), angle=30.0)
    fine = _anisotropic_noise(rng, side, (0.5, 6.0), angle=30.0)
    return 0.5 + 0.17 * streaks + 0.06 * fine


GENERATORS: dict[str, Callable[[np.random.Generator], Float]] = {
    "stones": _stones,
    "wood_rings": _wood_rings,
    "bark": _bark,
    "marble": _marble,
    "bricks": _bricks,
    "fabric": _fabric,
    "leopard": _leopard,
    "ripples": _ripples,
    "clouds": _clouds,
    "cracked": _cracked,
    "pebbles": _pebbles,
    "drift": _drift,
    "furrows": _furrows,
}


def procedural_names() -> list[str]:
    """Names of the procedural textures, in a fixed order."""
    return list(GENERATORS)


def _seed(name: str) -> int:
    """A seed of the texture's own, from its name (stable across Python runs)."""
    return int.from_bytes(hashlib.sha256(f"quality-texture:{name}".encode()).digest()[:8], "little")


def generate(name: str) -> Texture:
    """Make the procedural texture ``name`` (no cache): uint8, (H, W) or (H, W, 3)."""
    if name not in GENERATORS:
        raise KeyError(f"no procedural texture {name!r}; there are {', '.join(GENERATORS)}")
    return _to_uint8(GENERATORS[name](np.random.default_rng(_seed(name))))


def procedural(name: str, *, cache: bool = True) -> Texture:
    """The procedural texture ``name``, from the cache under ``benchmarks/.cache`` if there.

    Parameters
    ----------
    name : str
        One of :func:`procedural_names`.
    cache : bool
        Read and write the cache (``.npy`` files; the same bytes as :func:`generate`).
    """
    if not cache:
        return generate(name)
    path = CACHE / f"v{VERSION}" / f"{name}.npy"
    if path.exists():
        cached: Texture = np.load(path)
        return cached
    image = generate(name)
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_suffix(f".{np.random.default_rng().integers(1 << 30)}.tmp.npy")
    np.save(partial, image)
    partial.replace(path)
    return image


#: Photographs in the repository that are not textures: transfer targets ("camera" and "cat"
#: are copies of the targets in examples/).
TARGETS = ("camera", "cat")


def photos() -> dict[str, Path]:
    """The photographic textures of the repository, by name.

    ``tests/data/*.png`` and ``examples/*.png``, leaving out transfer targets (``target_*``,
    and ``camera``/``cat`` in examples), the outputs and boards of examples (every name there
    with an underscore: ``brick_synth``, ``variant_*``, ``alpha_*``, ...; ``web_page`` is a
    screenshot) and RGBA textures (``cloud_rgba``: quilted with alpha quilting, not the
    ``cut`` mode these benchmarks vary). A file with the same bytes as one already listed is
    listed once (``examples/brick.png`` is ``tests/data/brick.png``). Today: brick, grass,
    gravel, hubble and wood (see ``tests/data/README.md`` for their licences).
    """
    found: dict[str, Path] = {}
    seen: set[str] = set()
    for folder in (ROOT / "tests" / "data", ROOT / "examples"):
        for path in sorted(folder.glob("*.png")):
            name = path.stem
            if name.startswith("target_") or name in TARGETS or "_" in name:
                continue
            if name.endswith("rgba") or _has_alpha(path):
                continue
            digest = hashlib.sha256(path.read_bytes()).hexdigest()
            if digest in seen or name in found:
                continue
            seen.add(digest)
            found[name] = path
    return dict(sorted(found.items()))


def _has_alpha(path: Path) -> bool:
    """Whether a PNG's header declares an alpha channel (colour type 4 or 6) or a tRNS chunk."""
    data = path.read_bytes()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        return False
    if data[25] in (4, 6):
        return True
    return b"tRNS" in data[: data.find(b"IDAT")]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--png", type=Path, help="write every procedural texture here as PNG")
    args = parser.parse_args()
    for name in procedural_names():
        image = procedural(name)
        kind = "RGB" if image.ndim == 3 else "gray"
        print(f"{name:<11} {image.shape[1]}x{image.shape[0]} {kind:<4} mean {image.mean():6.1f}")
        if args.png:
            import quilting  # only here: the generators themselves need numpy and scipy only

            args.png.mkdir(parents=True, exist_ok=True)
            quilting.write_image(args.png / f"{name}.png", image)
    for name, path in photos().items():
        print(f"photo {name:<11} {path.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
