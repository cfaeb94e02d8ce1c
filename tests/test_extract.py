"""Alpha from an ordinary photo (quilting.extract_alpha) and the jobs that take a photo with a
trimap or scribbles (synthesize, matte)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import quilting
from quilting import BASE_BYTES, Budget, JobTooLargeError
from quilting.core.trimap import UNKNOWN

DATA = Path(__file__).resolve().parent / "data"

SIDE = 80


def _scene() -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """A known alpha (the cloud's, resized), a known smooth foreground, two backgrounds."""
    cloud = Image.open(DATA / "cloud_rgba.png").resize((SIDE, SIDE), Image.Resampling.LANCZOS)
    alpha = np.asarray(cloud, dtype=np.float64)[..., 3] / 255
    yy, xx = np.mgrid[0:SIDE, 0:SIDE] / (SIDE - 1)
    foreground = np.stack([0.9 - 0.3 * yy, 0.75 + 0 * xx, 0.35 + 0.4 * xx], -1)
    backgrounds = [
        np.stack([0.1 + 0.2 * xx, 0.15 + 0 * xx, 0.5 - 0.3 * yy], -1),
        np.stack([0.3 + 0 * xx, 0.05 + 0.3 * yy, 0.1 + 0 * xx], -1),
    ]
    return alpha, foreground, backgrounds


def _photo(alpha: np.ndarray, foreground: np.ndarray, background: np.ndarray) -> np.ndarray:
    composite = alpha[..., None] * foreground + (1 - alpha[..., None]) * background
    return np.round(composite * 255).astype(np.uint8)


def _trimap(alpha: np.ndarray) -> np.ndarray:
    marks = np.full(alpha.shape, 128, np.uint8)
    marks[alpha > 0.97] = 255
    marks[alpha < 0.03] = 0
    return marks


@pytest.fixture(scope="module")
def scene() -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    return _scene()


# Mean absolute error of the alpha and of the foreground colour (where alpha > 0.1) each
# method stays under on the two composites (measured: cf 0.016 / 0.029 and 0.017 / 0.027,
# lkm 0.002 / 0.019 and 0.009 / 0.031, knn 0.067 / 0.066 and 0.092 / 0.100); the photo's own
# colour is 0.24-0.26 off the foreground there.
BOUNDS = {"cf": (0.04, 0.04), "lkm": (0.04, 0.045), "knn": (0.09, 0.12)}


@pytest.mark.parametrize("method", sorted(BOUNDS))
@pytest.mark.parametrize("which", [0, 1])
def test_known_alpha_and_foreground_are_recovered(
    scene: tuple[np.ndarray, np.ndarray, list[np.ndarray]], method: str, which: int
) -> None:
    alpha, foreground, backgrounds = scene
    photo = _photo(alpha, foreground, backgrounds[which])
    found = quilting.extract_alpha(photo, _trimap(alpha), method=method)
    alpha_bound, colour_bound = BOUNDS[method]
    assert np.abs(found.alpha - alpha).mean() < alpha_bound
    seen = alpha > 0.1
    colour = found.image[..., :3].astype(np.float64) / 255
    error = np.abs(colour - foreground)[seen].mean()
    assert error < colour_bound
    # The photo's colour keeps the background showing through: far worse.
    assert np.abs(photo / 255 - foreground)[seen].mean() > 2.5 * error
    assert found.method == method and found.iterations >= 1


def test_photo_foreground_keeps_the_photos_colour(
    scene: tuple[np.ndarray, np.ndarray, list[np.ndarray]],
) -> None:
    alpha, foreground, backgrounds = scene
    photo = _photo(alpha, foreground, backgrounds[0])
    found = quilting.extract_alpha(photo, _trimap(alpha), foreground="photo")
    assert np.array_equal(found.image[..., :3], photo)
    assert found.foreground == "photo"


def test_known_pixels_are_exact_and_the_result_is_reproducible(
    scene: tuple[np.ndarray, np.ndarray, list[np.ndarray]],
) -> None:
    alpha, foreground, backgrounds = scene
    photo, marks = _photo(alpha, foreground, backgrounds[1]), _trimap(alpha)
    found = quilting.extract_alpha(photo, marks)
    assert found.image.shape == (SIDE, SIDE, 4) and found.image.dtype == np.uint8
    assert (found.alpha[marks == 255] == 1).all() and (found.image[marks == 255, 3] == 255).all()
    assert (found.alpha[marks == 0] == 0).all() and (found.image[marks == 0, 3] == 0).all()
    assert np.array_equal(found.trimap == UNKNOWN, marks == 128)
    again = quilting.extract_alpha(photo, marks)
    assert again.image.tobytes() == found.image.tobytes()
    assert set(found.summary()) == {"method", "foreground", "unknown", "iterations", "seconds"}
    assert found.summary()["unknown"] == pytest.approx((marks == 128).mean(), abs=1e-4)


def test_scribbles_alone_find_an_alpha(
    scene: tuple[np.ndarray, np.ndarray, list[np.ndarray]],
) -> None:
    alpha, foreground, backgrounds = scene
    photo = _photo(alpha, foreground, backgrounds[0])
    strokes = np.zeros((SIDE, SIDE, 4), np.uint8)
    rows = np.arange(SIDE)[:, None] % 8 < 2  # a few horizontal strokes
    strokes[rows & (alpha > 0.97)] = (255, 255, 255, 255)
    strokes[rows & (alpha < 0.03)] = (0, 0, 0, 255)
    found = quilting.extract_alpha(photo, scribbles=strokes)
    assert found.unknown > 0.7
    assert np.abs(found.alpha - alpha).mean() < 0.08


@pytest.mark.parametrize("dtype", [np.uint16, np.float32])
def test_the_texture_has_the_photos_depth(
    scene: tuple[np.ndarray, np.ndarray, list[np.ndarray]], dtype: type
) -> None:
    alpha, foreground, backgrounds = scene
    photo8 = _photo(alpha, foreground, backgrounds[0])
    photo = (photo8.astype(np.uint16) * 257) if dtype == np.uint16 else photo8 / np.float32(255)
    found = quilting.extract_alpha(photo.astype(dtype), _trimap(alpha))
    assert found.image.dtype == dtype and found.image.shape == (SIDE, SIDE, 4)
    full = 65535 if dtype == np.uint16 else 1.0
    assert (found.image[_trimap(alpha) == 255, 3] == full).all()


def test_a_gray_photo_gives_gray_colour(
    scene: tuple[np.ndarray, np.ndarray, list[np.ndarray]],
) -> None:
    alpha, _, _ = scene
    gray = np.round((0.8 * alpha + 0.2 * (1 - alpha)) * 255).astype(np.uint8)
    found = quilting.extract_alpha(gray, _trimap(alpha))
    assert found.image.shape == (SIDE, SIDE, 4)
    assert np.array_equal(found.image[..., 0], found.image[..., 2])


def test_progress_is_reported_and_can_stop_the_solve(
    scene: tuple[np.ndarray, np.ndarray, list[np.ndarray]],
) -> None:
    alpha, foreground, backgrounds = scene
    photo = _photo(alpha, foreground, backgrounds[0])
    seen: list[tuple[float, str]] = []
    quilting.extract_alpha(
        photo, _trimap(alpha), method="knn", progress=lambda f, s: seen.append((f, s))
    )
    stages = [stage for _, stage in seen]
    assert "alpha" in stages and stages[-1] == "foreground" and seen[-1][0] == 1.0
    assert all(0.0 <= f <= 1.0 for f, _ in seen)

    class StopError(Exception):
        pass

    def stop(fraction: float, stage: str) -> None:
        raise StopError

    with pytest.raises(StopError):
        quilting.extract_alpha(photo, _trimap(alpha), method="knn", progress=stop)


def test_a_budget_is_checked_before_any_work() -> None:
    photo = np.zeros((2000, 2000, 3), np.uint8)
    marks = np.full((2000, 2000), 128, np.uint8)
    marks[0], marks[-1] = 255, 0
    with pytest.raises(JobTooLargeError, match="smaller photo"):
        quilting.extract_alpha(photo, marks, budget=Budget(memory_bytes=BASE_BYTES + (64 << 20)))
    with pytest.raises(JobTooLargeError, match="would take about"):
        quilting.extract_alpha(photo, marks, budget=Budget(seconds=1.0))
    estimate = quilting.estimate_extract(quilting.AlphaOptions(method="knn"), (2000, 2000))
    cheaper = quilting.estimate_extract(quilting.AlphaOptions(method="cf"), (2000, 2000))
    assert estimate.peak_bytes > cheaper.peak_bytes > BASE_BYTES


def test_bad_inputs_are_named(scene: tuple[np.ndarray, np.ndarray, list[np.ndarray]]) -> None:
    alpha, foreground, backgrounds = scene
    photo = _photo(alpha, foreground, backgrounds[0])
    with pytest.raises(quilting.InvalidTrimapError, match="is 40x80 but the photo is 80x80"):
        quilting.extract_alpha(photo, _trimap(alpha)[:, :40])
    with pytest.raises(quilting.InvalidImageError, match="already has an alpha"):
        quilting.extract_alpha(np.dstack([photo, photo[..., :1]]), _trimap(alpha))
    with pytest.raises(quilting.InvalidParameterError, match="method"):
        quilting.extract_alpha(photo, _trimap(alpha), method="magic")
    with pytest.raises(TypeError, match="did you mean 'method'"):
        quilting.extract_alpha(photo, _trimap(alpha), methods="cf")


def test_check_extract_refuses_what_extract_alpha_refuses(
    scene: tuple[np.ndarray, np.ndarray, list[np.ndarray]],
) -> None:
    """The checks alone (what the service runs before queueing): the same errors with the
    same words, and nothing for inputs the extraction takes."""
    alpha, foreground, backgrounds = scene
    photo, marks = _photo(alpha, foreground, backgrounds[0]), _trimap(alpha)
    assert quilting.check_extract(photo, marks) is None
    assert quilting.check_extract(photo, scribbles=marks) is None
    bad = [
        (photo, marks[:, :40], None),
        (np.dstack([photo, photo[..., :1]]), marks, None),
        (photo, np.full_like(marks, 128), None),
        (photo, None, None),
        (photo[:4, :4], marks[:4, :4], None),
    ]
    for image, trimap, scribbles in bad:
        with pytest.raises(quilting.InvalidImageError) as expected:
            quilting.extract_alpha(image, trimap, scribbles)
        with pytest.raises(type(expected.value), match=re.escape(expected.value.message)):
            quilting.check_extract(image, trimap, scribbles)


def test_synthesize_from_a_photo_and_trimap_is_synthesize_from_the_extracted_texture(
    scene: tuple[np.ndarray, np.ndarray, list[np.ndarray]],
) -> None:
    alpha, foreground, backgrounds = scene
    photo, marks = _photo(alpha, foreground, backgrounds[0]), _trimap(alpha)
    result = quilting.synthesize(photo, (96, 112), trimap=marks, block=24, seed=5)
    extracted = quilting.extract_alpha(photo, marks)
    direct = quilting.synthesize(extracted.image, (96, 112), block=24, seed=5)
    assert result.image.shape == (96, 112, 4)
    assert result.image.tobytes() == direct.image.tobytes()
    assert len(result.extracted) == 1
    assert result.extracted[0].image.tobytes() == extracted.image.tobytes()
    assert result.timings["extract"] > 0 and "extract" not in direct.timings
    assert direct.extracted == ()


def test_progress_of_a_job_with_an_extraction_only_grows(
    scene: tuple[np.ndarray, np.ndarray, list[np.ndarray]],
) -> None:
    """The extraction is the first half of the job's progress, the quilting the rest: the
    fractions a caller (the service's job status, a progress bar) sees never go back."""
    alpha, foreground, backgrounds = scene
    photo, marks = _photo(alpha, foreground, backgrounds[0]), _trimap(alpha)
    seen: list[tuple[float, str]] = []
    quilting.synthesize(
        photo, (64, 64), trimap=marks, block=24, seed=5, progress=lambda f, s: seen.append((f, s))
    )
    fractions = [fraction for fraction, _ in seen]
    assert fractions == sorted(fractions) and fractions[-1] == pytest.approx(1.0)
    stages = [stage for _, stage in seen]
    assert stages[0] == "alpha" and "foreground" in stages
    assert all(f <= 0.5 for f, stage in seen if stage in ("alpha", "foreground"))
    assert any(f > 0.5 for f, stage in seen if stage not in ("alpha", "foreground"))


def test_several_examples_take_one_map_each(
    scene: tuple[np.ndarray, np.ndarray, list[np.ndarray]],
) -> None:
    alpha, foreground, backgrounds = scene
    photo, marks = _photo(alpha, foreground, backgrounds[0]), _trimap(alpha)
    already = quilting.extract_alpha(_photo(alpha, foreground, backgrounds[1]), marks, method="knn")
    result = quilting.synthesize(
        [photo, already.image], (64, 64), trimap=[marks, None], matting="knn", block=24, seed=2
    )
    assert [found.method for found in result.extracted] == ["knn"]
    assert result.image.shape == (64, 64, 4)
    with pytest.raises(quilting.InvalidImageError, match="a list of 2 images"):
        quilting.synthesize([photo, already.image], (64, 64), trimap=[marks], block=24)
    with pytest.raises(quilting.InvalidImageError, match="not a list"):
        quilting.synthesize(photo, (64, 64), trimap=[marks], block=24)


def test_a_matte_layer_may_be_a_photo_with_a_trimap(
    scene: tuple[np.ndarray, np.ndarray, list[np.ndarray]],
) -> None:
    alpha, foreground, backgrounds = scene
    photo, marks = _photo(alpha, foreground, backgrounds[0]), _trimap(alpha)
    target = np.full((64, 64), 150, np.uint8)
    silhouette = np.zeros((64, 64), np.uint8)
    silhouette[8:56, 8:56] = 255
    gravel = np.asarray(Image.open(DATA / "gravel.png"))[:64, :64]
    result = quilting.matte(
        target,
        [gravel, photo],
        silhouette=silhouette,
        trimap=[None, marks],
        block=16,
        light=(0.0, 0.0, 1.0),
        seed=1,
    )
    assert result.image.shape[:2] == (64, 64)
    assert result.layers[0].extracted == ()
    assert len(result.layers[1].extracted) == 1
    assert result.layers[1].image.shape[2] == 4  # quilted by alpha quilting
