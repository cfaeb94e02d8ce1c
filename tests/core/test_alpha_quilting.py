"""Alpha quilting (alpha quilting and texture matting paper, §2.1): premultiplied error, the
alpha-histogram term, epsilon and the factored sampling by seam cost, on the shared RGBA cloud
texture."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PIL import Image

import quilting
from quilting.core.alpha import (
    BINS,
    alpha_histogram,
    bhattacharyya,
    factored_pick,
    histogram_mismatch,
)
from quilting.core.options import SynthesisOptions
from quilting.core.pixels import compared

DATA = Path(__file__).resolve().parents[1] / "data"


@pytest.fixture(scope="module")
def cloud() -> np.ndarray:
    return np.asarray(Image.open(DATA / "cloud_rgba.png"))


def rho_with_texture(texture: np.ndarray, alpha: np.ndarray) -> float:
    return float(
        bhattacharyya(alpha_histogram(texture[..., 3] / 255), alpha_histogram(alpha / 255))
    )


def test_auto_is_alpha_for_rgba_and_cut_otherwise(cloud: np.ndarray) -> None:
    options = SynthesisOptions()
    assert options.mode == "auto"
    assert options.resolved_mode(4) == "alpha" and options.resolved_mode(3) == "cut"
    result = quilting.synthesize(cloud, (96, 96), block=32, backend="fft")
    assert result.layout.meta["mode"] == "alpha"
    plain = quilting.synthesize(cloud[..., :3], (96, 96), block=32, backend="fft")
    assert plain.layout.meta["mode"] == "cut"


def test_alpha_mode_needs_alpha(cloud: np.ndarray) -> None:
    with pytest.raises(quilting.InvalidParameterError) as info:
        quilting.synthesize(cloud[..., :3], (96, 96), block=32, mode="alpha")
    assert info.value.parameter == "mode"


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_output_keeps_the_alpha_histogram(cloud: np.ndarray, seed: int) -> None:
    result = quilting.synthesize(cloud, (256, 256), block=32, seed=seed, backend="fft")
    assert result.image.shape == (256, 256, 4) and result.image.dtype == np.uint8
    assert rho_with_texture(cloud, result.image[..., 3]) >= 0.9


def test_colour_under_zero_alpha_does_not_change_the_choice(cloud: np.ndarray) -> None:
    """Premultiplied colour: junk where alpha is 0 leaves every block and seam as it was."""
    junk = cloud.copy()
    clear = junk[..., 3] == 0
    assert clear.mean() > 0.2  # the texture has plenty of clear pixels
    rng = np.random.default_rng(5)
    junk[clear, :3] = rng.integers(0, 256, size=(int(clear.sum()), 3), dtype=np.uint8)
    a = quilting.synthesize(cloud, (200, 180), block=32, seed=3, backend="fft")
    b = quilting.synthesize(junk, (200, 180), block=32, seed=3, backend="fft")
    assert a.layout.to_json() == b.layout.to_json()
    # ...while plain quilting of all four channels does see the junk.
    c = quilting.synthesize(cloud, (200, 180), block=32, seed=3, backend="fft", mode="cut")
    d = quilting.synthesize(junk, (200, 180), block=32, seed=3, backend="fft", mode="cut")
    assert c.layout.to_json() != d.layout.to_json()


def test_same_seed_same_bytes_on_every_backend(cloud: np.ndarray) -> None:
    a = quilting.synthesize(cloud, (160, 150), block=32, seed=9, backend="fft")
    b = quilting.synthesize(cloud, (160, 150), block=32, seed=9, backend="fft")
    assert a.image.tobytes() == b.image.tobytes()
    r = quilting.synthesize(cloud, (160, 150), block=32, seed=9, backend="reference")
    assert r.image.tobytes() == a.image.tobytes()
    other = quilting.synthesize(cloud, (160, 150), block=32, seed=10, backend="fft")
    assert other.image.tobytes() != a.image.tobytes()


@pytest.mark.gl
def test_gl_gives_the_same_bytes(cloud: np.ndarray, gl: Any) -> None:
    a = quilting.synthesize(cloud, (140, 130), block=32, seed=4, backend="fft")
    g = quilting.synthesize(cloud, (140, 130), block=32, seed=4, backend=gl.GLBackend())
    assert g.image.tobytes() == a.image.tobytes()


def test_every_pixel_and_its_alpha_come_from_one_source_pixel(cloud: np.ndarray) -> None:
    """Alpha is merged along the same seams as the colour: the layout re-renders all four."""
    result = quilting.synthesize(cloud, (150, 170), block=32, seed=2, backend="fft", tileable="x")
    assert np.array_equal(quilting.apply_layout(result.layout, cloud), result.image)


def test_premultiplied_comparison() -> None:
    pixels = np.array([[[1.0, 0.5, 0.25, 0.5], [0.3, 0.3, 0.3, 0.0]]], dtype=np.float32)
    assert np.allclose(compared(pixels, "rgb", premultiply=True), [[[0.5, 0.25, 0.125], [0, 0, 0]]])
    lum = compared(pixels, "luminance", premultiply=True)
    assert lum.shape == (1, 2, 1)
    assert np.isclose(lum[0, 0, 0], 0.5 * (0.299 + 0.587 * 0.5 + 0.114 * 0.25), atol=1e-6)
    assert lum[0, 1, 0] == 0


def test_histogram_mismatch_matches_brute_force() -> None:
    rng = np.random.default_rng(1)
    alpha = rng.random((23, 19)) ** 2
    alpha[:5] = 0.0
    alpha[-3:] = 1.0
    block = 7
    got = histogram_mismatch(alpha, block)
    assert got.shape == (23 - block + 1, 19 - block + 1)
    texture = np.histogram(alpha, bins=BINS, range=(0, 1))[0] / alpha.size
    for y in range(got.shape[0]):
        for x in range(got.shape[1]):
            window = alpha[y : y + block, x : x + block]
            counts = np.histogram(window, bins=BINS, range=(0, 1))[0] / window.size
            assert got[y, x] == pytest.approx(1 - np.sqrt(texture * counts).sum(), abs=1e-12)


def test_bhattacharyya_bounds() -> None:
    p = alpha_histogram(np.linspace(0, 1, 1000))
    assert bhattacharyya(p, p) == pytest.approx(1.0)
    q = alpha_histogram(np.zeros(10))
    r = alpha_histogram(np.ones(10))
    assert bhattacharyya(q, r) == 0.0


def test_factored_sampling_follows_exp_minus_eta_e() -> None:
    costs = np.array([0.0, 0.05, 0.1, 0.4])
    eta = 10.0
    rng = np.random.default_rng(0)
    draws = np.bincount([factored_pick(costs, eta, rng) for _ in range(20000)], minlength=4)
    expected = np.exp(-eta * costs) / np.exp(-eta * costs).sum()
    assert np.allclose(draws / draws.sum(), expected, atol=0.015)
    # eta = 0 draws uniformly; a huge eta takes the cheapest.
    uniform = np.bincount([factored_pick(costs, 0.0, rng) for _ in range(8000)], minlength=4) / 8000
    assert np.allclose(uniform, 0.25, atol=0.03)
    assert {factored_pick(costs, 1e6, rng) for _ in range(50)} == {0}


def test_the_options_change_the_result(cloud: np.ndarray) -> None:
    base = quilting.synthesize(cloud, (128, 128), block=32, seed=1, backend="fft").layout
    for change in ({"histogram_weight": 1.0}, {"epsilon": 0.5}, {"eta": 0.0}):
        other = quilting.synthesize(cloud, (128, 128), block=32, seed=1, backend="fft", **change)
        assert other.layout.to_json() != base.to_json(), change
        assert other.layout.meta[next(iter(change))] == next(iter(change.values()))


def test_alpha_histogram_is_kept_at_least_as_well_as_by_plain_rgb_quilting(
    cloud: np.ndarray,
) -> None:
    """Over eight seeds, alpha quilting's worst coefficient is at least plain RGB quilting's
    (colour matched, the alpha carried by the same layout), and its mean no worse than the
    seeds' spread. On this texture both stay near 0.997: the differences are small."""
    alpha_mode, plain = [], []
    for seed in range(8):
        result = quilting.synthesize(cloud, (192, 192), block=32, seed=seed, backend="fft")
        alpha_mode.append(rho_with_texture(cloud, result.image[..., 3]))
        rgb = quilting.synthesize(cloud[..., :3], (192, 192), block=32, seed=seed, backend="fft")
        plain.append(rho_with_texture(cloud, quilting.apply_layout(rgb.layout, cloud[..., 3])))
    assert min(alpha_mode) >= 0.9
    assert min(alpha_mode) >= min(plain)
    assert np.mean(alpha_mode) >= np.mean(plain) - np.std(plain)
