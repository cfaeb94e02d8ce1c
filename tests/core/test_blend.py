"""Tests of the seam blend: zero without a seam, the least-squares solution of a dense solver,
a brightness step spread away, cells independent of their batch; through the engine, results
that are their layouts rendered, whatever the batch, and a drifting texture's steps gone."""

from __future__ import annotations

import json

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy.sparse import lil_matrix
from scipy.sparse.linalg import lsqr
from textures import texture

import quilting
from quilting.core.blend import OVERSHOOT, SCREEN, cell_corrections
from quilting.core.errors import InvalidParameterError, LayoutError
from quilting.core.layout import Layout


def _case(
    seed: int, n: int = 3, side: int = 9, channels: int = 2
) -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.bool_], NDArray[np.bool_]]:
    """Random cells with a left cut and a top cut in a strip of 3 (like an L overlap)."""
    rng = np.random.default_rng(seed)
    old = rng.random((n, side, side, channels), dtype=np.float32)
    new = rng.random((n, side, side, channels), dtype=np.float32)
    y, x = np.mgrid[0:side, 0:side]
    cut_x = rng.integers(0, 4, (n, side))  # per row
    cut_y = rng.integers(0, 4, (n, side))  # per column
    owned = (x[None] >= cut_x[:, :, None]) & (y[None] >= cut_y[:, None, :])
    covered = np.broadcast_to((x < 3) | (y < 3), (n, side, side)).copy()
    return old, new, owned, covered


def _dense(
    old: NDArray[np.float32],
    new: NDArray[np.float32],
    owned: NDArray[np.bool_],
    covered: NDArray[np.bool_],
    screen: float,
) -> NDArray[np.float64]:
    """The same least-squares problem by a sparse solver, edge by edge: an edge inside the cell
    wants the pasted difference, except across the cut, where it wants the mean of both
    images' differences (the block's own where the canvas does not cover both ends); every
    edge to the ring around the cell wants c = 0, and each pixel wants ``sqrt(screen) c = 0``."""
    n, side, _, channels = old.shape
    out = np.zeros(old.shape)
    index = np.arange(side * side).reshape(side, side)
    for k in range(n):
        pasted = np.where(owned[k][..., None], new[k], old[k]).astype(np.float64)
        for c in range(channels):
            equations, targets = [], []
            for dy, dx in ((1, 0), (0, 1)):
                for y in range(side - dy):
                    for x in range(side - dx):
                        here, there = (y, x), (y + dy, x + dx)
                        change = 0.0
                        if owned[k][here] != owned[k][there]:
                            wanted = float(new[k][there][c]) - float(new[k][here][c])
                            if covered[k][here] and covered[k][there]:
                                wanted += float(old[k][there][c]) - float(old[k][here][c])
                                wanted /= 2
                            change = OVERSHOOT * (wanted - (pasted[there][c] - pasted[here][c]))
                        equations.append(((index[there], 1.0), (index[here], -1.0)))
                        targets.append(change)
            for y in range(side):
                for x in range(side):
                    for _ in range((y == 0) + (y == side - 1) + (x == 0) + (x == side - 1)):
                        equations.append(((index[y, x], 1.0),))
                        targets.append(0.0)
                    equations.append(((index[y, x], np.sqrt(screen)),))
                    targets.append(0.0)
            matrix = lil_matrix((len(equations), side * side))
            for row, terms in enumerate(equations):
                for column, value in terms:
                    matrix[row, column] = value
            solved = lsqr(matrix.tocsr(), np.array(targets), atol=1e-12, btol=1e-12)[0]
            out[k, :, :, c] = solved.reshape(side, side)
    return out


def test_no_seam_no_correction() -> None:
    old, new, _, covered = _case(1)
    everywhere = np.ones(old.shape[:3], dtype=bool)
    assert not cell_corrections(old, new, everywhere, covered).any()
    assert not cell_corrections(old, new, ~everywhere, covered).any()


@pytest.mark.parametrize("screen", [0.0, SCREEN, 2.0])
@pytest.mark.parametrize("seed", [2, 3])
def test_the_correction_is_the_least_squares_solution(seed: int, screen: float) -> None:
    old, new, owned, covered = _case(seed)
    found = cell_corrections(old, new, owned, covered, screen=screen)
    np.testing.assert_allclose(found, _dense(old, new, owned, covered, screen), atol=2e-5)
    if screen == SCREEN:
        np.testing.assert_array_equal(found, cell_corrections(old, new, owned, covered))


def test_a_brightness_step_across_the_cut_is_taken_off_near_it() -> None:
    side = 40
    rng = np.random.default_rng(4)
    texture = (0.05 * rng.random((1, side, side, 1))).astype(np.float32)
    old, new = texture + np.float32(0.2), texture + np.float32(0.6)  # the same grain, a step
    _, x = np.mgrid[0:side, 0:side]
    owned = np.broadcast_to(x >= 4, (1, side, side)).copy()
    covered = np.broadcast_to(x < 8, (1, side, side)).copy()
    pasted = np.where(owned[..., None], new, old)
    blended = pasted + cell_corrections(old, new, owned, covered)

    def step(image: NDArray[np.float32]) -> float:
        inner = slice(side // 4, 3 * side // 4)  # away from the cell's ends, pinned at 0
        return float(np.abs(image[0, inner, 4, 0] - image[0, inner, 3, 0]).mean())

    assert step(pasted) > 0.3
    # Screened and asked OVERSHOOT times, the solve takes 2 / (3 + SCREEN - r) * OVERSHOOT of
    # a straight step off the cut (r + 1 / r = 2 + SCREEN): what is left is a fraction.
    r = (2 + SCREEN - np.sqrt((2 + SCREEN) ** 2 - 4)) / 2
    left = abs(1 - OVERSHOOT * 2 / (3 + SCREEN - r))
    assert step(blended) < (left + 0.1) * step(pasted)
    # The step is spread over a few pixels each side of the cut, not across the cell: 8 pixels
    # away the change is a small fraction of it.
    change = np.abs(blended - pasted)[0, :, :, 0]
    assert change[:, 12:].max() < 0.02 * step(pasted)
    assert change[:, 3:5].mean() > 0.25 * step(pasted)


def test_cells_do_not_depend_on_their_batch() -> None:
    old, new, owned, covered = _case(5, n=6, side=17, channels=3)
    together = cell_corrections(old, new, owned, covered)
    for k in range(6):
        alone = cell_corrections(
            old[k : k + 1], new[k : k + 1], owned[k : k + 1], covered[k : k + 1]
        )
        np.testing.assert_array_equal(alone[0], together[k])


# --- through the engine -----------------------------------------------------------------------


@pytest.mark.parametrize(
    "options",
    [{}, {"mode": "overlap"}, {"tileable": "both"}, {"mode": "random"}],
    ids=["cut", "overlap", "tileable", "random"],
)
@pytest.mark.parametrize("name", ["gravel", "hubble"])
def test_a_blended_result_is_its_layout_rendered_whatever_the_batch(
    name: str, options: dict[str, str]
) -> None:
    sample = texture(name)[:128, :128]
    result = quilting.synthesize(sample, (150, 130), block=32, seed=3, blend="poisson", **options)
    one = quilting.synthesize(
        sample, (150, 130), block=32, seed=3, blend="poisson", max_batch=1, **options
    )
    plain = quilting.synthesize(sample, (150, 130), block=32, seed=3, blend="none", **options)
    assert np.array_equal(result.image, one.image)
    assert result.image.dtype == sample.dtype and result.image.shape[:2] == (150, 130)
    assert not np.array_equal(result.image, plain.image)  # the blend changed something
    # (Later blocks are matched against the blended canvas, so their choices may differ.)
    assert result.layout.passes[0].blend == "poisson" and plain.layout.passes[0].blend == "none"
    again = Layout.from_json(result.layout.to_json())
    assert np.array_equal(quilting.apply_layout(again, sample), result.image)


def test_a_blended_transfer_is_its_layout_rendered() -> None:
    sample, target = texture("gravel")[:96, :96], texture("target_camera")[:80, :100]
    # Unshaded: the transfer's final shading is not part of the layout.
    result = quilting.transfer(sample, target, block=16, iterations=2, blend="poisson", shade=1)
    assert np.array_equal(quilting.apply_layout(result.layout, sample), result.image)


def test_the_blend_takes_the_step_off_a_drifting_texture() -> None:
    """A texture whose brightness drifts left to right: blocks from its two ends meet with a
    step; blended, the steps across the cuts are a fraction of the plain cut's."""
    rng = np.random.default_rng(7)
    ramp = np.linspace(0.15, 0.85, 160, dtype=np.float32)[None, :]
    drift = np.clip(ramp + 0.04 * rng.standard_normal((160, 160), dtype=np.float32), 0, 1)

    def seam_steps(blend: str) -> float:
        result = quilting.synthesize(drift, (200, 200), block=32, seed=1, blend=blend)
        grid = result.layout.passes[0].grid
        image = result.image
        # The vertical overlap strips' columns (cuts run there) against the cores' columns.
        strip = [
            c
            for j in range(1, grid.cols)
            for c in range(j * grid.step, j * grid.step + grid.overlap)
        ]
        core = [c for c in range(image.shape[1] - 1) if c not in strip and c + 1 not in strip]
        steps = np.abs(np.diff(image, axis=1))
        return float(
            steps[:, [c for c in strip if c < image.shape[1] - 1]].mean() / steps[:, core].mean()
        )

    assert seam_steps("poisson") < seam_steps("none")
    assert seam_steps("poisson") < 1.15  # the strips' steps look like the cores'


def test_a_blend_past_the_integer_range_is_clipped_not_wrapped() -> None:
    """Black and white squares: blended seams overshoot [0, 1]; in uint8 they are clipped
    (a float past 255 cast to uint8 would wrap round to black)."""
    rng = np.random.default_rng(0)
    squares = np.kron(rng.random((12, 12)) > 0.5, np.ones((8, 8))).astype(np.float32)
    floats = quilting.synthesize(squares, (200, 200), block=24, seed=1, blend="poisson").image
    assert floats.min() < 0 or floats.max() > 1  # the case this is about
    eight = (squares * 255).astype(np.uint8)
    result = quilting.synthesize(eight, (200, 200), block=24, seed=1, blend="poisson").image
    expected = np.rint(np.clip(floats, 0, 1) * np.float32(255)).astype(np.uint8)
    assert np.array_equal(result, expected)
    assert np.array_equal(
        quilting.apply_layout(
            quilting.synthesize(eight, (200, 200), block=24, seed=1, blend="poisson").layout, eight
        ),
        expected,
    )


def test_blend_values_are_checked() -> None:
    with pytest.raises(InvalidParameterError, match="blend"):
        quilting.synthesize(texture("gravel"), (64, 64), blend="smooth")  # type: ignore[arg-type]
    data = quilting.synthesize(texture("gravel")[:64, :64], (80, 80), block=16, blend="poisson")
    text = data.layout.to_json().replace('"blend":"poisson"', '"blend":"smudge"')
    with pytest.raises(LayoutError, match="blend"):
        Layout.from_json(text)


# --- companion maps ---------------------------------------------------------------------------


def _blended(size: int = 96) -> tuple[NDArray[np.uint8], quilting.Result]:
    sample = texture("hubble")[:size, :size]  # RGB
    return sample, quilting.synthesize(sample, (130, 120), block=24, seed=2, blend="poisson")


def test_a_hard_companion_is_never_mixed() -> None:
    """Material IDs quilted 'hard' with a blended layout: every pixel is one of the map's,
    the one the same blocks and cuts give without the blend; 'blend' would mix them."""
    sample, result = _blended()
    ids = np.arange(sample.shape[0] * sample.shape[1], dtype=np.uint16).reshape(sample.shape[:2])
    hard = quilting.apply_layout(result.layout, ids, kind="hard")
    document = json.loads(result.layout.to_json())
    for record in document["passes"]:
        del record["blend"]
    unblended = Layout.from_json(json.dumps(document))
    assert unblended.passes[0].blend == "none"
    assert np.array_equal(hard, quilting.apply_layout(unblended, ids))
    assert np.isin(hard, ids).all()
    mixed = quilting.apply_layout(result.layout, ids)  # IDs averaged across the seams
    assert (mixed != hard).sum() > 100


def test_a_normal_companion_stays_unit_length() -> None:
    sample, result = _blended()
    rng = np.random.default_rng(3)
    vectors = rng.normal(size=(*sample.shape[:2], 3))
    vectors[..., 2] = np.abs(vectors[..., 2]) + 0.2
    vectors /= np.linalg.norm(vectors, axis=-1, keepdims=True)
    normals = np.rint((vectors + 1) * 127.5).astype(np.uint8)

    def lengths(image: NDArray[np.uint8]) -> NDArray[np.float64]:
        return np.linalg.norm(image.astype(np.float64) / 127.5 - 1, axis=-1)

    source = lengths(normals)
    blended = lengths(quilting.apply_layout(result.layout, normals))
    renormalized = lengths(quilting.apply_layout(result.layout, normals, kind="normal"))
    tolerance = np.abs(source - 1).max() + 0.01  # 8-bit steps
    assert np.abs(blended - 1).max() > 2 * tolerance  # blending shortened some vectors
    assert np.abs(renormalized - 1).max() <= tolerance


def test_companion_kinds_are_the_same_without_a_blend() -> None:
    sample = texture("hubble")[:96, :96]
    layout = quilting.synthesize(sample, (130, 120), block=24, seed=2, blend="none").layout
    plain = quilting.apply_layout(layout, sample)
    for kind in ("hard", "normal"):
        assert np.array_equal(quilting.apply_layout(layout, sample, kind=kind), plain)


def test_companion_kinds_are_checked() -> None:
    sample, result = _blended()
    with pytest.raises(LayoutError, match="kind"):
        quilting.apply_layout(result.layout, sample, kind="soft")
    with pytest.raises(LayoutError, match="3 or 4 channels"):
        quilting.apply_layout(result.layout, sample[..., 0], kind="normal")
    walk = quilting.synthesize(sample, (130, 120), block=24, seed=2, mode="walk").layout
    with pytest.raises(LayoutError, match="walk"):
        quilting.apply_layout(walk, sample, kind="hard")
