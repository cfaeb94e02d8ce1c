"""Tests of make_tileable's gradient-domain blend (``blend="poisson"``, seamless_blend.py).

The solver against a dense least-squares reference on small grids, the cut edges against brute
force, the whole blend against the least-squares problem it states, and on images: the steps
along the cuts of a brightness ramp, the mean, alpha, dtypes, determinism, ``blend="none"``'s
bytes and companion maps through :meth:`Tiled.apply`.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray
from PIL import Image as PILImage
from scipy import sparse

from quilting.core.errors import InvalidImageError, InvalidParameterError
from quilting.core.options import TILE_BLENDS as OPTION_BLENDS
from quilting.core.options import TileOptions
from quilting.core.seamless import TILE_BLENDS, Axes, Tiled, make_tileable
from quilting.core.seamless_blend import (
    blend_selection,
    cut_edges,
    divergence,
    periodic_axes,
    poisson_correction,
)

Image = NDArray[np.generic]
DATA = Path(__file__).resolve().parents[1] / "data"
AXES: list[Axes] = ["both", "x", "y"]
PERIODIC = [(True, True), (False, True), (True, False)]
#: sha256 of ``make_tileable(tests/data/<name>.png).image`` computed with the code before the
#: blend existed (and checked against it when written): ``blend="none"`` must stay bit for bit.
#: To refresh on purpose: print ``hashlib.sha256(make_tileable(img, blend="none").image...)``.
GOLDEN = {
    "wood": "e12b7f3fd0c487eae1417dd0d790f11af73d094eb42cbab1db3370bf809876cf",
    "cloud_rgba": "667cc4ded12e2c7cad4290347c477114dca5fca4510fc467bb07128e2c78fbb8",
}


# --- references -------------------------------------------------------------------------------


def grid_edges(shape: tuple[int, int], periodic: tuple[bool, bool]) -> list[tuple[int, int, int]]:
    """Every edge (axis, p, q) of the output grid, flat indices, wrap edges where periodic."""
    height, width = shape
    edges = []
    for y in range(height):
        for x in range(width):
            if y + 1 < height or periodic[0]:
                edges.append((0, y * width + x, ((y + 1) % height) * width + x))
            if x + 1 < width or periodic[1]:
                edges.append((1, y * width + x, y * width + (x + 1) % width))
    return edges


def incidence(shape: tuple[int, int], edges: list[tuple[int, int, int]]) -> sparse.csr_array:
    """The gradient operator: one row per edge, ``c[q] - c[p]``."""
    rows = np.repeat(np.arange(len(edges)), 2)
    cols = np.array([[p, q] for _, p, q in edges]).reshape(-1)
    values = np.tile([-1.0, 1.0], len(edges))
    return sparse.csr_array((values, (rows, cols)), shape=(len(edges), shape[0] * shape[1]))


def reference_solve(rhs: NDArray[np.float64], periodic: tuple[bool, bool]) -> NDArray[np.float64]:
    """The zero-mean ``c`` with ``laplacian(c) = rhs``, the Laplacian ``-G^T G`` of the grid's
    own edges, solved densely (least squares: the Laplacian is singular, constants)."""
    gradient = incidence(rhs.shape, grid_edges(rhs.shape, periodic))
    laplacian = -(gradient.T @ gradient).toarray()
    solved = np.linalg.lstsq(laplacian, rhs.reshape(-1), rcond=None)[0]
    return (solved - solved.mean()).reshape(rhs.shape)


def brute_cut_edges(source: NDArray[np.intp], axis: int, periodic: bool) -> set[tuple[int, int]]:
    width = source.shape[1]
    found = set()
    for a, p, q in grid_edges(source.shape, (periodic, False) if axis == 0 else (False, periodic)):
        if a != axis:
            continue
        sp, sq = int(source.flat[p]), int(source.flat[q])
        (py, px), (qy, qx) = divmod(sp, width), divmod(sq, width)
        neighbour = (qy, qx) == ((py + 1, px) if axis == 0 else (py, px + 1))
        if not neighbour:
            found.add((p, q))
    return found


def source_map(t: Tiled) -> NDArray[np.intp]:
    return (t.source_rows * t.source_rows.shape[1] + t.source_cols).astype(np.intp)


def ramp_image(texture: Image, strength: float = 0.6) -> NDArray[np.uint8]:
    """A texture under a strong linear brightness ramp across x and y (a photo lit from one
    corner): ``(1 - s) * texture + s * ramp``, uint8."""
    height, width = texture.shape[:2]
    y, x = np.mgrid[0:height, 0:width]
    ramp = (x / (width - 1) * 0.5 + y / (height - 1) * 0.5)[..., None]
    base = texture.astype(np.float64) / 255.0
    base = base[..., None] if base.ndim == 2 else base
    mixed = (1 - strength) * base + strength * ramp
    return np.clip(np.rint(mixed * 255), 0, 255).astype(np.uint8)


def steps(t: Tiled, image: Image | None = None) -> tuple[float, float]:
    """Mean |difference| across the cut edges and across every other edge of the output
    (``image``, default ``t.image``), wrap edges of the tiled axes included."""
    out = (t.image if image is None else image).astype(np.float64)
    out = out[..., None] if out.ndim == 2 else out
    flat = out.reshape(-1, out.shape[2])
    source = source_map(t)
    periodic = periodic_axes(t.axes)
    cut_sum, cut_n, other_sum, other_n = 0.0, 0, 0.0, 0
    for axis in (0, 1):
        p, q = cut_edges(source, axis, periodic[axis])
        cut = np.abs(flat[q] - flat[p]).mean(axis=1)
        cut_sum, cut_n = cut_sum + cut.sum(), cut_n + cut.size
        shifted = np.roll(out, -1, axis=axis)
        every = np.abs(shifted - out).mean(axis=2)
        if not periodic[axis]:
            every = every[:-1] if axis == 0 else every[:, :-1]
        other_sum += every.sum() - cut.sum()
        other_n += every.size - cut.size
    return cut_sum / cut_n, other_sum / other_n


@pytest.fixture(scope="module")
def cloud_rgba() -> Image:
    return np.asarray(PILImage.open(DATA / "cloud_rgba.png"))


@pytest.fixture(scope="module")
def ramp(gravel: Image) -> NDArray[np.uint8]:
    return ramp_image(gravel)


# --- the solver -------------------------------------------------------------------------------


@pytest.mark.parametrize("periodic", PERIODIC)
@pytest.mark.parametrize("shape", [(5, 7), (6, 8), (8, 5), (4, 4)])
def test_solver_matches_dense_laplacian_solve(
    periodic: tuple[bool, bool], shape: tuple[int, int]
) -> None:
    rng = np.random.default_rng(shape[0] * 10 + shape[1])
    rhs = rng.standard_normal(shape)
    rhs -= rhs.mean()  # a divergence sums to 0: the problem is solvable
    expected = reference_solve(rhs, periodic)
    got = poisson_correction([rhs.astype(np.float32)], periodic)
    assert got.dtype == np.float32 and got.shape == shape
    assert abs(float(got.mean())) < 1e-5
    np.testing.assert_allclose(got, expected, atol=2e-5 * np.abs(expected).max())


@pytest.mark.parametrize("axes", AXES)
def test_cut_edges_match_brute_force(axes: Axes) -> None:
    rng = np.random.default_rng(3)
    image = rng.random((14, 18, 3))
    source = source_map(make_tileable(image, axes=axes, blend="none"))
    periodic = periodic_axes(axes)
    for axis in (0, 1):
        p, q = cut_edges(source, axis, periodic[axis])
        got = set(zip(p.tolist(), q.tolist(), strict=True))
        assert len(got) == p.size
        assert got == brute_cut_edges(source, axis, periodic[axis]), axis


@pytest.mark.parametrize("axes", AXES)
def test_blend_is_the_least_squares_fit_of_the_guidance(axes: Axes) -> None:
    """``O + c`` with ``c`` minimizing ``sum over edges (grad c - (v - grad O))^2``, ``v`` the mean
    of both sides' input gradients on the cut edges: built edge by edge here."""
    rng = np.random.default_rng(5)
    height, width = 12, 16
    image = rng.random((height, width, 1))
    source = source_map(make_tileable(image, axes=axes, blend="none"))
    periodic = periodic_axes(axes)
    edges = grid_edges((height, width), periodic)
    flat, values = source.reshape(-1), image.reshape(-1)
    cuts = {
        (p, q)
        for axis in (0, 1)
        for p, q in zip(*cut_edges(source, axis, periodic[axis]), strict=True)
    }
    wanted = np.zeros(len(edges))
    for row, (axis, p, q) in enumerate(edges):
        if (p, q) not in cuts:
            continue
        sp, sq = int(flat[p]), int(flat[q])
        step = width if axis == 0 else 1
        sides = []
        if (sp // width < height - 1) if axis == 0 else (sp % width < width - 1):
            sides.append(values[sp + step] - values[sp])
        if (sq // width > 0) if axis == 0 else (sq % width > 0):
            sides.append(values[sq] - values[sq - step])
        wanted[row] = np.mean(sides) - (values[sq] - values[sp])
    gradient = incidence((height, width), edges)
    fit = sparse.linalg.lsqr(gradient, wanted, atol=1e-12, btol=1e-12)[0]
    fit -= fit.mean()
    expected = values[flat] + fit
    got = blend_selection(image, source, axes)
    np.testing.assert_allclose(got.reshape(-1), expected, atol=1e-5)
    # The divergence alone, against the reference's: G^T (wanted) with the sign of laplacian.
    rhs = divergence(
        image.reshape(-1, 1),
        source,
        [(axis, *cut_edges(source, axis, periodic[axis])) for axis in (0, 1)],
        0,
    )
    np.testing.assert_allclose(rhs.reshape(-1), -(gradient.T @ wanted), atol=1e-6)


def test_nothing_to_blend_is_returned_unchanged() -> None:
    """A brightness ramp along y tiled along x: across the cuts (same rows) the two sides are
    equal and the y gradients the ramp's own, so the guidance asks for no change at all."""
    rows = np.arange(40, dtype=np.uint8)[:, None, None] * 3
    image = np.broadcast_to(rows, (40, 64, 3)).copy()
    none = make_tileable(image, axes="x", blend="none")
    blended = make_tileable(image, axes="x", blend="poisson")
    assert blended.image.tobytes() == none.image.tobytes()
    source = source_map(none)
    assert blend_selection(image, source, "x").tobytes() == none.image.tobytes()


# --- on images --------------------------------------------------------------------------------


@pytest.mark.parametrize("axes", AXES)
def test_ramp_steps_along_the_cuts_are_gone(ramp: Image, axes: Axes) -> None:
    none = make_tileable(ramp, axes=axes, blend="none")
    blended = make_tileable(ramp, axes=axes, blend="poisson")
    cut_none, other_none = steps(none)
    cut_blend, other_blend = steps(blended)
    # Without the blend the ramp's jump shows along the cuts, well over the texture's own
    # neighbour differences; with it the cut edges are like any other edge.
    assert cut_none > 2.0 * other_none
    assert cut_blend < 0.5 * cut_none
    assert cut_blend < 1.3 * other_blend
    # Same cuts, same sources; the mean brightness kept (within rounding and clipping).
    np.testing.assert_array_equal(blended.source_rows, none.source_rows)
    np.testing.assert_array_equal(blended.kept, none.kept)
    assert blended.seam_error == none.seam_error
    assert abs(float(blended.image.mean()) - float(none.image.mean())) < 0.5


def test_wrap_of_a_two_by_two_tiling_stays_seamless(ramp: Image) -> None:
    blended = make_tileable(ramp, blend="poisson").image.astype(np.float64)
    tiled = np.tile(blended, (2, 2, 1))
    height, width = blended.shape[:2]
    across_x = np.abs(tiled[:, width] - tiled[:, width - 1]).mean()
    across_y = np.abs(tiled[height] - tiled[height - 1]).mean()
    inside = np.abs(np.diff(blended, axis=1)).mean()
    assert across_x < 1.5 * inside and across_y < 1.5 * inside


def test_rgba_alpha_is_not_blended(cloud_rgba: Image) -> None:
    image = ramp_image(cloud_rgba[..., :3])
    image = np.concatenate([image, cloud_rgba[..., 3:]], axis=2)
    none = make_tileable(image, blend="none")
    blended = make_tileable(image, blend="poisson")
    np.testing.assert_array_equal(blended.image[..., 3], none.image[..., 3])
    assert not np.array_equal(blended.image[..., :3], none.image[..., :3])


@pytest.mark.parametrize("dtype", ["uint8", "uint16", "float32", "float64"])
@pytest.mark.parametrize("shape", [(48, 40), (48, 40, 1), (48, 40, 3), (48, 40, 4)])
def test_dtypes_and_shapes(dtype: str, shape: tuple[int, ...]) -> None:
    rng = np.random.default_rng(len(shape))
    unit = ramp_image((rng.random(shape) * 255).astype(np.uint8)).astype(np.float64) / 255
    unit = unit.reshape(shape)
    image: Image
    if dtype in ("uint8", "uint16"):
        top = np.iinfo(dtype).max
        image = np.rint(unit * top).astype(dtype)
    else:
        image = unit.astype(dtype)
    t = make_tileable(image, blend="poisson")
    assert t.image.shape == image.shape and t.image.dtype == image.dtype
    assert t.blend == "poisson" and t.axes == "both"
    none = make_tileable(image, blend="none")
    scale = 1.0 if dtype.startswith("float") else float(np.iinfo(dtype).max)
    # The correction is smooth: at most the largest step of a cut, far less than the range.
    change = np.abs(t.image.astype(np.float64) - none.image.astype(np.float64)) / scale
    assert 0 < change.max() < 0.6
    assert abs((t.image.astype(np.float64).mean() - none.image.mean()) / scale) < 2e-3


def test_deterministic(ramp: Image) -> None:
    first = make_tileable(ramp, blend="poisson").image.tobytes()
    assert make_tileable(ramp.copy(), blend="poisson").image.tobytes() == first


@pytest.mark.parametrize("name", sorted(GOLDEN))
def test_blend_none_is_the_bytes_of_before(name: str, request: pytest.FixtureRequest) -> None:
    image = request.getfixturevalue(name)
    none = make_tileable(image, blend="none")
    assert hashlib.sha256(none.image.tobytes()).hexdigest() == GOLDEN[name]
    assert none.blend == "none"
    # The default blends (what measures best, issue 20), the cuts the same.
    default = make_tileable(image)
    assert default.blend == "poisson" and default.image.tobytes() != none.image.tobytes()
    assert np.array_equal(default.source_rows, none.source_rows)


def test_bad_blend_is_refused(gravel: Image) -> None:
    with pytest.raises(InvalidParameterError) as caught:
        make_tileable(gravel, blend="gauss")  # type: ignore[arg-type]
    assert caught.value.parameter == "blend"
    with pytest.raises(InvalidParameterError) as from_options:
        TileOptions(blend="gauss")  # type: ignore[arg-type]
    assert from_options.value.parameter == "blend"


def test_blend_values_are_the_options() -> None:
    assert TILE_BLENDS == OPTION_BLENDS == ("none", "poisson")
    assert TileOptions().blend == "poisson"


# --- companion maps ---------------------------------------------------------------------------


def normal_map(shape: tuple[int, int]) -> NDArray[np.uint8]:
    """A tangent-space normal map of a bumpy surface with a tilt across it (a ramp in x)."""
    height, width = shape
    y, x = np.mgrid[0:height, 0:width]
    nx = 0.4 * x / width + 0.1 * np.sin(y / 3.0)
    ny = 0.1 * np.cos(x / 4.0)
    vectors = np.stack([nx, ny, np.ones_like(nx)], axis=2)
    vectors /= np.linalg.norm(vectors, axis=2, keepdims=True)
    return np.rint((vectors + 1) / 2 * 255).astype(np.uint8)


def test_apply_kinds(ramp: Image) -> None:
    blended = make_tileable(ramp, blend="poisson")
    none = make_tileable(ramp, blend="none")
    selection = ramp[blended.source_rows, blended.source_cols]
    # 'blend' of the image itself is the image; 'hard' the pure selection.
    np.testing.assert_array_equal(blended.apply(ramp), blended.image)
    np.testing.assert_array_equal(blended.apply(ramp, kind="hard"), selection)
    # Unblended, every kind is the selection.
    for kind in ("blend", "hard"):
        np.testing.assert_array_equal(none.apply(ramp, kind=kind), selection)
    normals = normal_map(ramp.shape[:2])
    np.testing.assert_array_equal(
        none.apply(normals, kind="normal"), normals[none.source_rows, none.source_cols]
    )


def test_apply_normal_renormalizes(ramp: Image) -> None:
    blended = make_tileable(ramp, blend="poisson")
    normals = normal_map(ramp.shape[:2])
    out = blended.apply(normals, kind="normal")
    assert out.dtype == np.uint8 and out.shape == normals.shape
    vectors = out.astype(np.float64) / 255 * 2 - 1
    length = np.linalg.norm(vectors, axis=2)
    assert np.abs(length - 1).max() < 0.02  # unit within uint8 rounding
    plain = blended.apply(normals, kind="blend").astype(np.float64) / 255 * 2 - 1
    assert np.abs(np.linalg.norm(plain, axis=2) - 1).max() > np.abs(length - 1).max()


def test_apply_checks_its_companion(ramp: Image) -> None:
    t = make_tileable(ramp, blend="poisson")
    with pytest.raises(InvalidImageError):
        t.apply(ramp[:-1])
    with pytest.raises(InvalidParameterError):
        t.apply(ramp, kind="soft")
    with pytest.raises(InvalidParameterError):
        t.apply(ramp[..., 0], kind="normal")
