"""Wang tile sets (issue 25, :mod:`quilting.core.wang`): every pair of tiles whose touching
edges share a colour meets seamlessly, arrangements keep the edge rule, companions follow."""

from __future__ import annotations

import itertools
import json
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray
from tests.core.textures import texture

import quilting
from quilting.core.errors import InvalidParameterError
from quilting.core.wang import arrange, complete_edges, edge_rule_kept, tile_index
from quilting.costs.fft import FFTBackend
from quilting.costs.reference import ReferenceBackend

TILE, BLOCK = 48, 16


def sample(name: str = "hubble", side: int = 64) -> NDArray[Any]:
    return np.ascontiguousarray(texture(name)[:side, :side])


@pytest.fixture(scope="module", params=["poisson", "none"])
def tiles(request: pytest.FixtureRequest) -> quilting.WangTiles:
    return quilting.wang_tiles(sample(), tile=TILE, block=BLOCK, seed=3, blend=request.param)


def test_the_set_is_complete(tiles: quilting.WangTiles) -> None:
    assert tiles.tiles.shape == (16, TILE, TILE, 3)
    assert tiles.tiles.dtype == np.uint8
    assert len({tuple(e) for e in tiles.edges.tolist()}) == 16
    for k, (n, e, s, w) in enumerate(tiles.edges.tolist()):
        assert tile_index(n, e, s, w, 2) == k
    assert complete_edges(3).shape == (81, 4)


def _steps(a: NDArray[Any], b: NDArray[Any]) -> float:
    """Mean squared difference between two pixel columns (or rows)."""
    return float(((a.astype(np.float64) - b.astype(np.float64)) ** 2).mean())


def test_tiles_sharing_an_edge_colour_meet_seamlessly(tiles: quilting.WangTiles) -> None:
    """Across every matching edge, horizontal and vertical, the squared difference is at the
    level of neighbouring columns (rows) inside the tiles; across mismatched edges it is not."""
    t = tiles.tiles
    inner_cols = np.mean(
        [_steps(t[k][:, c], t[k][:, c + 1]) for k in range(16) for c in range(TILE - 1)]
    )
    inner_rows = np.mean([_steps(t[k][r], t[k][r + 1]) for k in range(16) for r in range(TILE - 1)])
    across, down, mismatched = [], [], []
    for a, b in itertools.product(range(16), repeat=2):
        ea, eb = tiles.edges[a], tiles.edges[b]
        (across if ea[1] == eb[3] else mismatched).append(_steps(t[a][:, -1], t[b][:, 0]))
        if ea[2] == eb[0]:
            down.append(_steps(t[a][-1], t[b][0]))
    assert len(across) == len(down) == 128
    assert np.mean(across) <= 1.25 * inner_cols, (np.mean(across), inner_cols)
    assert np.mean(down) <= 1.25 * inner_rows, (np.mean(down), inner_rows)
    assert max(across) <= 2.5 * inner_cols
    # The test can fail: a mismatched edge shows two unrelated diamonds.
    assert np.mean(mismatched) > 1.5 * np.mean(across)


def test_unblended_tiles_are_their_diamonds_pixel_for_pixel() -> None:
    """Without blending each pixel is its labelled diamond's, and the outline of a tile
    belongs to its edges' diamonds (the corners aside)."""
    made = quilting.wang_tiles(sample(), tile=TILE, block=BLOCK, seed=3, blend="none")
    material = quilting.apply_layout(made.material, sample())
    h = TILE // 2
    squares = [material[:, k * TILE : (k + 1) * TILE] for k in range(4)]
    for k, (n, e, s, w) in enumerate(made.edges.tolist()):
        labels = made.labels[k]
        assert (labels[0, 1:-1] == 0).all() and (labels[-1, 1:-1] == 2).all()
        assert (labels[1:-1, 0] == 3).all() and (labels[1:-1, -1] == 1).all()
        layers = {
            0: np.concatenate([squares[n][h:], squares[n][:h]]),
            2: np.concatenate([squares[s][h:], squares[s][:h]]),
            3: np.concatenate([squares[2 + w][:, h:], squares[2 + w][:, :h]], axis=1),
            1: np.concatenate([squares[2 + e][:, h:], squares[2 + e][:, :h]], axis=1),
        }
        # Each diamond only in its own half: north on top, south below, west left, east right.
        outside = {0: (slice(h, None), slice(None)), 2: (slice(0, h), slice(None)),
                   3: (slice(None), slice(h, None)), 1: (slice(None), slice(0, h))}  # fmt: skip
        for label, layer in layers.items():
            where = labels == label
            assert not where[outside[label]].any(), (k, label)
            assert np.array_equal(made.tiles[k][where], layer[where]), (k, label)


@pytest.mark.parametrize("wrap", [False, True])
@pytest.mark.parametrize("colors", [2, 3])
def test_arrangements_keep_the_edge_rule_and_do_not_repeat(colors: int, wrap: bool) -> None:
    edges = complete_edges(colors)
    for seed in range(5):
        grid = arrange(colors, 24, 31, seed, wrap=wrap)
        assert grid.shape == (24, 31) and edge_rule_kept(edges, grid, wrap=wrap)
        assert np.array_equal(grid, arrange(colors, 24, 31, seed, wrap=wrap))
        assert len(np.unique(grid)) > colors**4 // 2
        # Aperiodic in practice: no shift of a few tiles maps the arrangement onto itself.
        for dy, dx in itertools.product(range(4), range(4)):
            if dy or dx:
                assert not np.array_equal(grid[dy:, dx:], grid[: 24 - dy, : 31 - dx])
    broken = arrange(colors, 4, 4, 1)
    broken[1, 1] = tile_index(*((edges[broken[1, 1]] + [1, 0, 0, 0]) % colors), colors)
    assert not edge_rule_kept(edges, broken)


@pytest.mark.parametrize("blend", ["none", "poisson"])
def test_a_rendered_arrangement_is_seamless_everywhere(blend: str) -> None:
    """Across every join of an arrangement the two tiles show the two halves of one diamond:
    the very columns (rows) of its square, corners aside, blended or not (the blend inside a
    tile keeps its outline)."""
    made = quilting.wang_tiles(sample(), tile=TILE, block=BLOCK, seed=1, blend=blend)
    layout = made.arrange(4, 5, seed=2)
    image = made.render(layout)
    assert image.shape == (4 * TILE, 5 * TILE, 3)
    assert np.array_equal(image[TILE : 2 * TILE, 2 * TILE : 3 * TILE], made.tiles[layout[1, 2]])
    material = quilting.apply_layout(made.material, sample())
    h, t = TILE // 2, TILE
    joins, own = [], []
    for i, j in itertools.product(range(4), range(5)):
        _, e, s, _ = made.edges[layout[i, j]].tolist()
        cell = (slice(i * t + 1, (i + 1) * t - 1), slice(j * t + 1, (j + 1) * t - 1))
        if j < 4:
            square = material[:, (2 + e) * t : (3 + e) * t]
            pair = image[cell[0], (j + 1) * t - 1 : (j + 1) * t + 1]
            expected = square[1:-1, h - 1 : h + 1]
            joins.append(_steps(pair[:, 0], pair[:, 1]))
            own.append(_steps(expected[:, 0], expected[:, 1]))
            assert np.array_equal(pair, expected), (i, j, "east")
        if i < 3:
            square = material[:, s * t : (s + 1) * t]
            pair = image[(i + 1) * t - 1 : (i + 1) * t + 1, cell[1]]
            expected = square[h - 1 : h + 1, 1:-1]
            joins.append(_steps(pair[0], pair[1]))
            own.append(_steps(expected[0], expected[1]))
            assert np.array_equal(pair, expected), (i, j, "south")
    assert np.mean(joins) <= 1.25 * np.mean(own), (np.mean(joins), np.mean(own))
    atlas = made.atlas()
    assert atlas.shape == (4 * TILE, 4 * TILE, 3)
    manifest = json.loads(made.to_json())
    assert manifest["format"] == "quilting.wang" and len(manifest["tiles"]) == 16
    for entry in manifest["tiles"]:
        k, y, x = entry["index"], entry["y"], entry["x"]
        assert np.array_equal(atlas[y : y + TILE, x : x + TILE], made.tiles[k])
        assert [entry[e] for e in "nesw"] == made.edges[k].tolist()


def test_companions_follow_the_tiles() -> None:
    rgb = sample()
    made = quilting.wang_tiles(rgb, tile=TILE, block=BLOCK, seed=4)
    assert np.array_equal(made.apply(rgb), made.tiles)
    ids = (np.arange(64 * 64) % 251).astype(np.uint8).reshape(64, 64)
    hard = made.apply(ids, kind="hard")
    assert hard.shape == (16, TILE, TILE) and np.isin(hard, ids).all()


def test_several_examples_and_transforms_make_the_material() -> None:
    gravel = texture("gravel")
    sources = [np.ascontiguousarray(gravel[:56, :56]), np.ascontiguousarray(gravel[60:120, 40:90])]
    fft = quilting.wang_tiles(
        sources, tile=32, block=12, seed=2, transforms="all", backend=FFTBackend()
    )
    reference = quilting.wang_tiles(sources, tile=32, block=12, seed=2, transforms="all",
                                    backend=ReferenceBackend())  # fmt: skip
    assert fft.tiles.tobytes() == reference.tiles.tobytes()
    assert fft.tiles.shape == (16, 32, 32)
    assert set(np.unique(fft.material.provenance()["example"]).tolist()) == {0, 1}
    assert np.array_equal(fft.apply(sources), fft.tiles)


@pytest.mark.parametrize(
    ("options", "needle"),
    [({"tile": 47}, "even"), ({"colors": 5}, "colors"), ({"tile": 8}, "tile")],
)
def test_bad_options_are_refused(options: dict[str, Any], needle: str) -> None:
    with pytest.raises(InvalidParameterError, match=needle):
        quilting.wang_tiles(sample(), **options)


def test_the_cost_is_known_before_work() -> None:
    found = quilting.estimate_wang(quilting.WangOptions(colors=4, tile=1024), (128, 128, 3))
    small = quilting.estimate_wang(quilting.WangOptions(colors=2, tile=64), (128, 128, 3))
    # 256 tiles of 1024^2 RGB are held in floats and bytes: gigabytes, said before any work.
    assert found.peak_bytes > 256 * 1024**2 * 3 * 5 > small.peak_bytes
    with pytest.raises(quilting.JobTooLargeError):
        quilting.wang_tiles(
            sample(), colors=4, tile=1024, budget=quilting.Budget(memory_bytes=1 << 30)
        )
