"""Wang tile sets made by image quilting (Cohen, Shade, Hiller and Deussen 2003).

Every edge of a Wang tile carries a colour; two tiles may touch along an edge when the colours
there agree, and a complete set (every combination of C colours on the four edges, C^4 tiles)
tiles any plane, aperiodically when each tile is drawn at random among those that fit. Here,
as in the paper (§3.2, Fig. 4), each colour of the horizontal edges and each of the vertical
edges is a *diamond* of texture: a square ``tile x tile`` sample whose inscribed diamond is
centred on the edge, half of it in each tile that shares the edge. A tile is four diamond
halves, one per edge, meeting along its diagonals; the tile's outline runs through the middle
of its diamonds, so across any edge two tiles show the two halves of one diamond, continuous
pixel for pixel. Inside a tile, each quarter (between a corner and the centre) lies where two
diamonds overlap, and they are joined along a minimum cut there (the paper's quilting seams
along the diagonals; here the cut of least squared difference between the two, over the
quarter, from the tile's corner to its centre), then blended across the cut as synthesis
blends its seams (:mod:`quilting.core.blend`).

The diamonds are cut from one texture quilted from the examples (:func:`quilting.core.
synthesis.quilt`, so several examples and their rotations are material too); the layout of
that texture, the diamonds' places and the tiles' cuts replay on companion maps
(:meth:`WangTiles.apply`).

References
----------
.. [1] M. F. Cohen, J. Shade, S. Hiller and O. Deussen, "Wang Tiles for Image and Texture
       Generation", SIGGRAPH 2003, §3 (complete tile sets, the stochastic tiling of §3.1,
       tiles from diamond samples joined by quilting seams, §3.2).
.. [2] A. A. Efros and W. T. Freeman, "Image Quilting for Texture Synthesis and Transfer",
       SIGGRAPH 2001, §2 (the quilting of the material).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from quilting.core import kernels
from quilting.core.blend import cell_corrections
from quilting.core.errors import InvalidParameterError
from quilting.core.fields import CostBackend
from quilting.core.layout import Layout, apply_layout, check_companion_kind, renormalize
from quilting.core.options import WangOptions
from quilting.core.pixels import PixelFormat, as_channels, compared, from_working, to_working
from quilting.core.progress import Progress
from quilting.core.sources import NORMAL_KINDS, Examples, transformed
from quilting.core.synthesis import quilt

#: Pixel states of the quarters' cuts (those of :func:`quilting.core.kernels.region_cuts`,
#: whose module loads numba: not imported here before a cut is made).
FREE, OLD, NEW = 0, 1, 2

#: The order of a tile's edges in :attr:`WangTiles.edges`.
EDGES = ("n", "e", "s", "w")
FORMAT = "quilting.wang"
VERSION = 1
#: The quarter of a tile each of its four cuts runs in, and the transform taking the quarter
#: to the canonical one (the top-left: horizontal diamond on its top row and right column,
#: vertical diamond on its left column and bottom row).
_QUARTERS = (("tl", "identity"), ("tr", "flip_x"), ("bl", "flip_y"), ("br", "rot180"))


def tile_index(n: int, e: int, s: int, w: int, colors: int) -> int:
    """The index in a complete set of the tile with edge colours (n, e, s, w)."""
    return ((n * colors + e) * colors + s) * colors + w


def complete_edges(colors: int) -> NDArray[np.intp]:
    """Edge colours (n, e, s, w) of every tile of the complete set, shape (colors^4, 4)."""
    grid = np.indices((colors,) * 4).reshape(4, -1).T
    return np.ascontiguousarray(grid, dtype=np.intp)


def arrange(
    colors: int, rows: int, cols: int, seed: int = 0, *, wrap: bool = False
) -> NDArray[np.intp]:
    """An aperiodic arrangement of a complete set: Cohen et al.'s stochastic tiling (§3.1).

    Cells are filled row by row; each cell's north colour is that of the south edge above it
    and its west colour that of the east edge on its left (drawn at random on the first row
    and column), its east and south colours drawn at random, so that a complete set always
    has its tile. With ``wrap`` the last column's east colours are the first column's west
    ones and the last row's south colours the first row's north ones: the arrangement tiles
    the plane periodically with period (rows, cols), each edge rule kept across the wrap.

    Parameters
    ----------
    colors : int
        Colours per edge, >= 2.
    rows, cols : int
        Size of the arrangement in tiles, >= 1.
    seed : int
        The same seed gives the same arrangement.
    wrap : bool

    Returns
    -------
    ndarray of intp, shape (rows, cols)
        Tile indices (:func:`tile_index`).
    """
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x3A96]))
    south = rng.integers(colors, size=cols)  # the colours above the first row
    east = rng.integers(colors, size=rows)  # the colours left of the first column
    north_first, west_first = south.copy(), east.copy()
    tiles = np.empty((rows, cols), dtype=np.intp)
    for i in range(rows):
        west = int(east[i])
        for j in range(cols):
            n = int(south[j])
            e = int(west_first[i]) if wrap and j == cols - 1 else int(rng.integers(colors))
            s = int(north_first[j]) if wrap and i == rows - 1 else int(rng.integers(colors))
            tiles[i, j] = tile_index(n, e, s, west, colors)
            south[j], west = s, e
    return tiles


def edge_rule_kept(
    edges: NDArray[np.integer], arrangement: NDArray[np.integer], *, wrap: bool = False
) -> bool:
    """Whether every pair of neighbouring tiles of ``arrangement`` agrees on its shared edge
    (across the wrap too with ``wrap``)."""
    cells = edges[arrangement]  # (rows, cols, 4)
    across = cells[:, :-1, 1] == cells[:, 1:, 3]
    down = cells[:-1, :, 2] == cells[1:, :, 0]
    kept = bool(across.all() and down.all())
    if wrap:
        kept &= bool((cells[:, -1, 1] == cells[:, 0, 3]).all())
        kept &= bool((cells[-1, :, 2] == cells[0, :, 0]).all())
    return kept


@dataclass
class WangTiles:
    """A complete Wang tile set (what :func:`quilting.wang_tiles` returns).

    Attributes
    ----------
    tiles : ndarray, shape (colors^4, T, T) or (colors^4, T, T, C)
        The tiles, in the examples' dtype and channels; tile ``k`` has edge colours
        ``edges[k]``.
    edges : ndarray of intp, shape (colors^4, 4)
        Colours of each tile's north, east, south and west edges (:data:`EDGES`).
    colors : int
    tile : int
        T, the side of a tile.
    labels : ndarray of uint8, shape (colors^4, T, T)
        Which of the tile's diamonds each pixel shows (0 north, 1 east, 2 south, 3 west).
    material : Layout
        The layout of the texture the diamonds were cut from (``tile`` x ``2 colors tile``:
        horizontal colour ``c``'s diamond is its square ``c``, vertical colour ``c``'s the
        square ``colors + c``).
    blend : str
        'poisson' when the cuts inside the tiles were blended, else 'none'.
    timings : dict of str to float
        Seconds spent quilting the material, cutting and blending the tiles, and in all.
    meta : dict
        The options that made the set.
    backend, renderer, fallback : str, str or None, str or None
        What quilted the material, as :class:`~quilting.core.synthesis.Result` says.
    """

    tiles: NDArray[Any]
    edges: NDArray[np.intp]
    colors: int
    tile: int
    labels: NDArray[np.uint8]
    material: Layout
    blend: str
    timings: dict[str, float] = field(default_factory=dict)
    meta: dict[str, Any] = field(default_factory=dict)
    backend: str = "none"
    renderer: str | None = None
    fallback: str | None = None

    def arrange(
        self, rows: int, cols: int, seed: int = 0, *, wrap: bool = False
    ) -> NDArray[np.intp]:
        """An aperiodic (rows, cols) arrangement of tile indices (:func:`arrange`)."""
        _check_count("rows", rows)
        _check_count("cols", cols)
        return arrange(self.colors, rows, cols, seed, wrap=wrap)

    def render(
        self, arrangement: NDArray[np.integer], tiles: NDArray[Any] | None = None
    ) -> NDArray[Any]:
        """The image of an arrangement: ``tiles[arrangement[i, j]]`` at row i, column j.

        Parameters
        ----------
        arrangement : ndarray of int, shape (rows, cols)
        tiles : ndarray, optional
            Tiles to lay out (default :attr:`tiles`; companion tiles from :meth:`apply`).

        Returns
        -------
        ndarray, shape (rows T, cols T) or (rows T, cols T, C)
        """
        tiles = self.tiles if tiles is None else tiles
        arrangement = np.asarray(arrangement, dtype=np.intp)
        if arrangement.ndim != 2 or arrangement.min() < 0 or arrangement.max() >= len(tiles):
            raise InvalidParameterError(
                "arrangement", arrangement.shape, f"a 2-D array of tile indices 0..{len(tiles) - 1}"
            )
        rows, cols = arrangement.shape
        t = self.tile
        picked = tiles[arrangement]  # (rows, cols, T, T, ...)
        order = (0, 2, 1, 3, *range(4, picked.ndim))
        image: NDArray[Any] = np.ascontiguousarray(picked.transpose(order)).reshape(
            rows * t, cols * t, *tiles.shape[3:]
        )
        return image

    @property
    def grid(self) -> tuple[int, int]:
        """(rows, cols) of the atlas: colors^2 by colors^2."""
        return self.colors**2, self.colors**2

    def atlas(self, tiles: NDArray[Any] | None = None) -> NDArray[Any]:
        """Every tile in one image, tile ``k`` at row ``k // cols``, column ``k % cols`` of
        :attr:`grid` (as :meth:`manifest` lists them)."""
        rows, cols = self.grid
        return self.render(np.arange(rows * cols).reshape(rows, cols), tiles)

    def manifest(self) -> dict[str, Any]:
        """The set's description for the atlas image, as JSON-able dict: the tile size, the
        colours, and for every tile its place in the atlas and its edge colours."""
        _, cols = self.grid
        t = self.tile
        return {
            "format": FORMAT,
            "version": VERSION,
            "tile": t,
            "colors": self.colors,
            "columns": cols,
            "rows": self.grid[0],
            "edges": list(EDGES),
            "tiles": [
                {
                    "index": k,
                    "x": (k % cols) * t,
                    "y": (k // cols) * t,
                    **{name: int(c) for name, c in zip(EDGES, self.edges[k], strict=True)},
                }
                for k in range(len(self.edges))
            ],
            "meta": self.meta,
        }

    def to_json(self) -> str:
        """:meth:`manifest` as a JSON document."""
        return json.dumps(self.manifest(), indent=1)

    def apply(self, companion: object, *, kind: str = "blend") -> NDArray[Any]:
        """The same tiles cut from a companion map (normal, roughness, height...).

        Parameters
        ----------
        companion : ndarray or list of ndarray
            As :func:`quilting.apply_layout` takes for the material's layout: a map of the
            example's size, or one per example.
        kind : {'blend', 'hard', 'normal', 'normal_dx'}
            As :func:`quilting.apply_layout`'s; 'hard' joins the tiles' cuts unblended.

        Returns
        -------
        ndarray, shape (colors^4, T, T) or (colors^4, T, T, C')
            Tile for tile with :attr:`tiles`, in the companion's dtype.
        """
        material = apply_layout(self.material, companion, kind=kind)
        view, fmt = as_channels(material, "companion")
        check_companion_kind(kind, view.shape[2], walk=False)
        blend = self.blend if kind != "hard" else "none"
        return _assemble(view, fmt, self.edges, self.labels, self.colors, self.tile, blend, kind)


def _check_count(name: str, value: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= 4096:
        raise InvalidParameterError(name, value, "1..4096")


def diamonds(material: NDArray[Any], colors: int, tile: int) -> NDArray[Any]:
    """The 2 colors diamond squares of the material, shape (2 colors, T, T, C): horizontal
    colours first, then vertical ones."""
    return np.stack([material[:, k * tile : (k + 1) * tile] for k in range(2 * colors)])


def _halves(
    squares: NDArray[Any], n: int, e: int, s: int, w: int, colors: int
) -> tuple[NDArray[Any], NDArray[Any]]:
    """A tile's two layers: its horizontal diamonds' halves (north on top, south below) and
    its vertical ones' (west on the left, east on the right), each (T, T, C)."""
    t = squares.shape[1]
    h = t // 2
    horizontal = np.concatenate([squares[n][h:], squares[s][:h]], axis=0)
    vertical = np.concatenate([squares[colors + w][:, h:], squares[colors + e][:, :h]], axis=1)
    return horizontal, vertical


#: Half-width of the band around a quarter's diagonal that its cut may wander in, as a share
#: of the quarter's side: the cut runs from the tile's corner to its centre near the diagonal
#: where the two diamonds meet (Cohen et al.'s seams along the diagonals), never along the
#: tile's outline, which must stay each edge's own diamond for neighbours to join it. A
#: quarter of the side leaves some 44 % of a quarter's pixels free, and the cuts about three
#: times faster than over the whole quarter.
BAND = 0.25


def _quarter_state(side: int) -> NDArray[np.int8]:
    """The canonical quarter's pixel states: NEW (the horizontal diamond) above the band
    around the diagonal from the top-left corner to the bottom-right (the quarter's top row
    and right column included), OLD (the vertical one) below it (the left column and bottom
    row), FREE in the band."""
    y, x = np.indices((side, side))
    band = max(1, round(BAND * side))
    state = np.full((side, side), FREE, dtype=np.int8)
    state[x - y > band] = NEW
    state[y - x > band] = OLD
    state[:, 0] = OLD
    state[-1, :] = OLD
    state[0, :] = NEW
    state[:, -1] = NEW
    state[-1, -1] = OLD  # the centre pixel: either
    return state


def tile_labels(
    squares: NDArray[np.float32], edges: NDArray[np.intp], colors: int
) -> NDArray[np.uint8]:
    """Every tile's minimum cuts: which diamond each pixel shows.

    A quarter's cut depends only on its two diamonds, so each of the 4 colors^2 distinct cuts
    is found once (:func:`quilting.core.kernels.region_cuts`).

    Parameters
    ----------
    squares : ndarray of float32, shape (2 colors, T, T, K)
        The diamonds' squares as the error compares them.
    edges : ndarray of intp, shape (n, 4)
    colors : int

    Returns
    -------
    ndarray of uint8, shape (n, T, T)
        0 north, 1 east, 2 south, 3 west.
    """
    t = squares.shape[1]
    h = t // 2
    state = _quarter_state(h)
    jobs: dict[tuple[str, int, int], int] = {}
    errors: list[NDArray[np.float32]] = []
    for n, e, s, w in edges.tolist():
        horizontal, vertical = _halves(squares, n, e, s, w, colors)
        for (quarter, turn), (hd, vd) in zip(
            _QUARTERS, ((n, w), (n, e), (s, w), (s, e)), strict=True
        ):
            key = (quarter, hd, vd)
            if key in jobs:
                continue
            window = _window(quarter, h)
            diff = horizontal[window] - vertical[window]
            jobs[key] = len(errors)
            errors.append(transformed(np.einsum("yxc,yxc->yx", diff, diff), turn))
    owned = kernels.region_cuts(
        np.ascontiguousarray(np.stack(errors), dtype=np.float64),
        np.ascontiguousarray(np.broadcast_to(state, (len(errors), h, h))),
    )
    labels = np.empty((len(edges), t, t), dtype=np.uint8)
    for k, (n, e, s, w) in enumerate(edges.tolist()):
        for (quarter, turn), (hd, vd, hl, vl) in zip(
            _QUARTERS, ((n, w, 0, 3), (n, e, 0, 1), (s, w, 2, 3), (s, e, 2, 1)), strict=True
        ):
            # The canonical cut back in the quarter's own orientation (each turn here is its
            # own inverse).
            horizontal_side = transformed(owned[jobs[(quarter, hd, vd)]], turn)
            labels[k][_window(quarter, h)] = np.where(horizontal_side, hl, vl)
    return labels


def _window(quarter: str, h: int) -> tuple[slice, slice]:
    rows = slice(0, h) if quarter[0] == "t" else slice(h, 2 * h)
    cols = slice(0, h) if quarter[1] == "l" else slice(h, 2 * h)
    return rows, cols


def _assemble(
    view: NDArray[Any],
    fmt: PixelFormat,
    edges: NDArray[np.intp],
    labels: NDArray[np.uint8],
    colors: int,
    tile: int,
    blend: str,
    kind: str = "blend",
) -> NDArray[Any]:
    """The tiles of a material (T, 2 colors T, C), cut by ``labels`` and blended."""
    working = to_working(view)
    squares = diamonds(working, colors, tile)
    channels = working.shape[2]
    blended = 3 if channels == 4 else channels  # an RGBA texture's alpha is not blended
    out = np.empty((len(edges), tile, tile, channels), dtype=np.float32)
    for k, (n, e, s, w) in enumerate(edges.tolist()):
        horizontal, vertical = _halves(squares, n, e, s, w, colors)
        owned = (labels[k] == 0) | (labels[k] == 2)
        tile_image = np.where(owned[..., None], horizontal, vertical)
        if blend == "poisson":
            # Solved inside the outline, which keeps its pixels: each edge stays its
            # diamond's, pixel for pixel, for the neighbours across it.
            inner = (slice(1, -1), slice(1, -1))
            covered = np.ones((1, tile - 2, tile - 2), dtype=bool)
            correction = cell_corrections(
                vertical[inner][None, ..., :blended],
                horizontal[inner][None, ..., :blended],
                owned[inner][None],
                covered,
            )[0]
            tile_image[1:-1, 1:-1, :blended] += correction
        out[k] = tile_image
    if kind in NORMAL_KINDS:
        renormalize(out.reshape(-1, tile, channels))
    converted = from_working(out, view.dtype)
    result = out.astype(view.dtype) if converted is None else converted
    return result[..., 0] if fmt.two_dimensional else result


def cut_tiles(
    material: NDArray[Any],
    fmt: PixelFormat,
    colors: int,
    tile: int,
    blend: str,
    error: str,
) -> tuple[NDArray[Any], NDArray[np.intp], NDArray[np.uint8], dict[str, float]]:
    """The complete set cut from a quilted material.

    Parameters
    ----------
    material : ndarray, shape (T, 2 colors T, C)
        The quilted texture in the examples' dtype.
    fmt : PixelFormat
    colors, tile : int
    blend : {'none', 'poisson'}
    error : {'rgb', 'luminance'}
        What the cuts compare.

    Returns
    -------
    tiles, edges, labels, timings
    """
    started = time.perf_counter()
    edges = complete_edges(colors)
    squares = diamonds(compared(to_working(material), error), colors, tile)
    labels = tile_labels(squares, edges, colors)
    cut = time.perf_counter()
    tiles = _assemble(material, fmt, edges, labels, colors, tile, blend)
    done = time.perf_counter()
    return tiles, edges, labels, {"cuts": cut - started, "tiles": done - cut}


def make_wang_tiles(
    examples: Examples,
    options: WangOptions,
    backend: CostBackend,
    *,
    progress: Progress | None = None,
    max_batch: int | None = None,
) -> WangTiles:
    """Quilt the material of a set from ``examples`` and cut its complete set of tiles.

    Parameters
    ----------
    examples : Examples
        The validated examples (:func:`quilting.core.sources.read_examples`).
    options : WangOptions
    backend : CostBackend
    progress : callable, optional
        ``progress(fraction, stage)``: 0..0.9 quilting ("material"), then 1.0 ("tiles").
    max_batch : int, optional

    Returns
    -------
    WangTiles
    """
    started = time.perf_counter()
    t, colors = options.tile, options.colors

    def material_progress(fraction: float, stage: str) -> None:
        if progress is not None:
            progress(0.9 * fraction, "material")

    quilted = quilt(
        examples.view,
        examples.fmt,
        (t, 2 * colors * t),
        options.synthesis(),
        backend,
        progress=material_progress,
        max_batch=max_batch,
        excluded=examples.excluded,
        sources=examples.sources,
        weights=examples.weights,
    )
    made = time.perf_counter()
    view, fmt = as_channels(quilted.image, "material")
    tiles, edges, labels, timings = cut_tiles(view, fmt, colors, t, options.blend, options.error)
    if progress is not None:
        progress(1.0, "tiles")
    meta = {"operation": "wang_tiles", **options.to_dict()}
    return WangTiles(
        tiles=tiles,
        edges=edges,
        colors=colors,
        tile=t,
        labels=labels,
        material=quilted.layout,
        blend=options.blend,
        timings={"material": made - started, **timings, "total": time.perf_counter() - started},
        meta=meta,
        backend=quilted.backend,
        renderer=quilted.renderer,
        fallback=quilted.fallback,
    )
