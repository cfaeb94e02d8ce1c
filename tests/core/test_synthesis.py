"""End-to-end synthesis: sizes, dtypes, determinism, the paper's ordering of modes, layouts."""

from __future__ import annotations

import numpy as np
import pytest

import quilting
from quilting import Layout, apply_layout, synthesize
from quilting.core.stats import ownership
from quilting.costs.fft import FFTBackend


def test_exact_output_size_for_odd_sizes(gravel) -> None:
    result = synthesize(gravel, (333, 517), seed=1)
    assert result.image.shape == (333, 517)
    assert result.image.dtype == np.uint8
    assert result.layout.output_shape == (333, 517)
    tiny = synthesize(gravel, (1, 1), seed=1)
    assert tiny.image.shape == (1, 1)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float16, np.float32, np.float64])
@pytest.mark.parametrize("channels", [None, 1, 3, 4])
def test_channels_and_dtype_are_kept(dtype, channels) -> None:
    rng = np.random.default_rng(0)
    shape = (40, 50) if channels is None else (40, 50, channels)
    if np.dtype(dtype).kind == "u":
        texture = rng.integers(0, np.iinfo(dtype).max, size=shape, endpoint=True).astype(dtype)
    else:
        texture = rng.random(shape).astype(dtype)
    result = synthesize(texture, (61, 75), block=12, seed=2, blend="none")
    assert result.image.dtype == texture.dtype
    assert result.image.shape == (61, 75, *shape[2:])
    # Every output pixel is a pixel of the texture, bit for bit.
    assert np.array_equal(apply_layout(result.layout, texture), result.image)
    flat_in = {tuple(p) for p in texture.reshape(40 * 50, -1).tolist()}
    assert all(tuple(p) in flat_in for p in result.image.reshape(61 * 75, -1)[::37].tolist())


def test_same_seed_same_bytes_different_seed_different(gravel) -> None:
    a = synthesize(gravel, (200, 230), seed=5)
    b = synthesize(gravel, (200, 230), seed=5)
    c = synthesize(gravel, (200, 230), seed=6)
    assert a.image.tobytes() == b.image.tobytes()
    assert a.layout.to_json() == b.layout.to_json()
    assert a.image.tobytes() != c.image.tobytes()


def _crop(texture: np.ndarray, side: int = 72) -> np.ndarray:
    return np.ascontiguousarray(texture[:side, :side])


@pytest.mark.parametrize("name", ["gravel", "brick", "hubble", "wood"])
def test_fft_and_reference_choose_the_same_blocks(request, name) -> None:
    texture = _crop(request.getfixturevalue(name))
    kwargs = {"block": 18, "seed": 9}
    fft = synthesize(texture, (90, 110), backend="fft", **kwargs)
    ref = synthesize(texture, (90, 110), backend="reference", **kwargs)
    assert fft.backend == "fft" and ref.backend == "reference"
    assert fft.image.tobytes() == ref.image.tobytes()
    assert np.array_equal(fft.layout.passes[0].positions, ref.layout.passes[0].positions)


def test_zero_tolerance_matches_reference_on_near_ties(gravel) -> None:
    # Tolerance 0 keeps only the exact minimum: any FFT round-off would show here.
    texture = _crop(gravel, 64)
    kwargs = {"block": 16, "seed": 4, "tolerance": 0.0, "min_candidates": 1}
    fft = synthesize(texture, (80, 80), backend="fft", **kwargs)
    ref = synthesize(texture, (80, 80), backend="reference", **kwargs)
    assert fft.image.tobytes() == ref.image.tobytes()


def test_batch_size_and_threads_do_not_change_the_output(hubble) -> None:
    base = synthesize(hubble, (260, 300), seed=3)
    one = synthesize(hubble, (260, 300), seed=3, max_batch=1)
    threaded = synthesize(hubble, (260, 300), seed=3, backend=FFTBackend(threads=2), max_batch=3)
    assert base.image.tobytes() == one.image.tobytes() == threaded.image.tobytes()


@pytest.mark.parametrize("name", ["brick", "gravel"])
def test_cut_beats_overlap_beats_random(request, name) -> None:
    texture = request.getfixturevalue(name)
    means = {}
    for mode in ("cut", "overlap", "random"):
        errors = [
            synthesize(texture, (300, 300), mode=mode, seed=s).stats.seam_error_mean for s in (1, 2)
        ]
        means[mode] = float(np.mean(errors))
    assert means["cut"] < means["overlap"] < means["random"], means


def test_boundary_discontinuity_in_the_image_follows_the_modes(brick) -> None:
    # Measured on the pixels, independently of the engine's own seam statistics: the mean
    # squared step across block boundaries in the output image.
    steps = {}
    for mode in ("cut", "overlap", "random"):
        result = synthesize(brick, (300, 300), mode=mode, seed=1)
        owner = ownership(result.layout).owner
        img = result.image.astype(np.float64) / 255
        across_x = owner[:, :-1] != owner[:, 1:]
        across_y = owner[:-1, :] != owner[1:, :]
        d = np.concatenate(
            [(img[:, :-1] - img[:, 1:])[across_x] ** 2, (img[:-1] - img[1:])[across_y] ** 2]
        )
        steps[mode] = float(d.mean())
    assert steps["cut"] < steps["overlap"] < steps["random"], steps


@pytest.mark.parametrize("mode", ["cut", "overlap", "random"])
def test_apply_layout_on_the_texture_reproduces_the_image(hubble, mode, tmp_path) -> None:
    result = synthesize(hubble, (201, 333), mode=mode, seed=8)
    assert np.array_equal(apply_layout(result.layout, hubble), result.image)
    path = tmp_path / "layout.json"
    result.layout.save(path)
    assert np.array_equal(apply_layout(Layout.load(path), hubble), result.image)


def test_apply_layout_on_a_companion_map(hubble) -> None:
    result = synthesize(hubble, (150, 170), seed=8)
    # A companion in another dtype and channel count: a 16-bit "height map" whose value encodes
    # the source pixel's position, so alignment can be checked pixel by pixel ('hard': the
    # blocks and cuts unmixed, as an ID map must be).
    yy, xx = np.indices(hubble.shape[:2])
    companion = (yy * 256 + xx).astype(np.uint16)
    quilted = apply_layout(result.layout, companion, kind="hard")
    assert quilted.shape == (150, 170) and quilted.dtype == np.uint16
    src_y, src_x = np.divmod(quilted.astype(np.int64), 256)
    assert np.array_equal(hubble[src_y, src_x], apply_layout(result.layout, hubble, kind="hard"))
    plain = synthesize(hubble, (150, 170), seed=8, blend="none")
    quilted = apply_layout(plain.layout, companion)
    src_y, src_x = np.divmod(quilted.astype(np.int64), 256)
    assert np.array_equal(hubble[src_y, src_x], plain.image)


def test_apply_layout_refuses_a_map_of_another_size(hubble) -> None:
    result = synthesize(hubble, (100, 100), seed=1)
    with pytest.raises(quilting.LayoutError, match="256x256"):
        apply_layout(result.layout, np.zeros((100, 120), np.uint8))


@pytest.mark.parametrize("name", ["gravel", "brick", "hubble"])
def test_outputs_do_not_reproduce_large_pieces_of_the_input(request, name) -> None:
    texture = request.getfixturevalue(name)
    stats = [synthesize(texture, (512, 512), seed=s).stats for s in (1, 2)]
    assert max(s.largest_copy for s in stats) < 0.2, stats


@pytest.mark.parametrize("name", ["gravel", "hubble"])
def test_the_floor_breaks_verbatim_continuations(request, name) -> None:
    # With the paper's bare rule (min_candidates=1) the best match is often the block's own
    # continuation in the source (cost ~0): the output copies far larger pieces.
    texture = request.getfixturevalue(name)
    default = np.mean([synthesize(texture, (512, 512), seed=s).stats.largest_copy for s in (1, 2)])
    greedy = np.mean(
        [
            synthesize(texture, (512, 512), seed=s, min_candidates=1).stats.largest_copy
            for s in (1, 2)
        ]
    )
    assert greedy > 2 * default, (greedy, default)


@pytest.mark.parametrize("name", ["gravel", "hubble"])
def test_seam_sampling_favours_the_cleanest_joins(request, name) -> None:
    # Factored sampling draws the cheaper seams more often: the mean seam error per seam
    # pixel falls as seam_sampling grows; 0 is the uniform draw.
    texture = request.getfixturevalue(name)

    def seam_error(sampling: float) -> float:
        runs = [
            synthesize(texture, (256, 256), seed=s, seam_sampling=sampling, tolerance=0.5)
            for s in (1, 2)
        ]
        return float(np.mean([r.stats.seam_error_mean for r in runs]))

    uniform, favoured, sharpest = seam_error(0.0), seam_error(4.0), seam_error(100.0)
    assert sharpest < favoured < uniform, (sharpest, favoured, uniform)


def test_seam_sampling_is_cut_modes_only(gravel) -> None:
    # Overlap mode has straight cuts: the option leaves it as it is.
    plain = synthesize(gravel, (120, 120), mode="overlap", seed=2, seam_sampling=0.0)
    other = synthesize(gravel, (120, 120), mode="overlap", seed=2, seam_sampling=50.0)
    np.testing.assert_array_equal(plain.image, other.image)
    cut = synthesize(gravel, (120, 120), mode="cut", seed=2, seam_sampling=0.0)
    sampled = synthesize(gravel, (120, 120), mode="cut", seed=2, seam_sampling=50.0)
    assert not np.array_equal(cut.image, sampled.image)


def test_progress_reaches_one_and_can_stop_the_job(gravel) -> None:
    seen: list[float] = []
    synthesize(gravel, (200, 200), progress=lambda f, stage: seen.append(f))
    assert seen == sorted(seen) and seen[-1] == 1.0 and len(seen) > 3

    def stop(fraction: float, stage: str) -> None:
        if fraction > 0.3:
            raise quilting.CancelledError("stopped by the caller")

    backend = FFTBackend(threads=2)
    with pytest.raises(quilting.CancelledError):
        synthesize(gravel, (200, 200), progress=stop, backend=backend)
    assert backend._pool is None and backend._spectrum is None  # released, no thread left over


def test_seam_overlay_marks_block_boundaries(gravel) -> None:
    result = synthesize(gravel, (120, 130), seed=1)
    overlay = result.seam_overlay()
    assert overlay.shape == (120, 130, 3) and overlay.dtype == np.uint8
    red = np.all(overlay == (255, 0, 0), axis=-1)
    # Roughly one seam line per block boundary: a few percent of the pixels.
    assert 0.01 < red.mean() < 0.2
    assert np.array_equal(overlay[~red][:, 0], result.image[~red])


def test_check_companion_kind_states_the_rules_render_applies(hubble) -> None:
    quilting.check_companion_kind("blend", 1, walk=True)
    quilting.check_companion_kind("normal", 3, walk=False)
    quilting.check_companion_kind("hard", 1, walk=False)
    for kind, channels, walk in (("soft", 3, False), ("normal", 2, False), ("hard", 1, True)):
        with pytest.raises(quilting.LayoutError):
            quilting.check_companion_kind(kind, channels, walk=walk)
    # Layout.render refuses the same.
    walked = synthesize(hubble[:96, :96], (100, 100), block=24, mode="walk", seed=1)
    with pytest.raises(quilting.LayoutError, match="walk"):
        apply_layout(walked.layout, hubble[:96, :96], kind="hard")
