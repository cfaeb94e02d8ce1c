"""The block map of a result: record it, save/load it as JSON, re-apply it to other maps.

A layout lists, for every block of every pass, the source position it was copied from and its
seam (the cut arrays of :mod:`quilting.core.seams`). Rendering a layout with the texture it was
made from reproduces the result exactly; rendering it with a companion map of the same size
(normal, roughness, height) gives that map quilted pixel-aligned with the result.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from quilting.core.blend import blend_cells
from quilting.core.compose import gather, paste
from quilting.core.errors import LayoutError
from quilting.core.grid import Grid
from quilting.core.options import BLENDS
from quilting.core.pixels import as_channels, from_working, to_working
from quilting.core.sources import NORMAL_KINDS, TRANSFORMS, SourceSet
from quilting.core.walk import fill_blocks, regions

Index = NDArray[np.intp]
Blocks = NDArray[Any]

FORMAT = "quilting.layout"
VERSION = 2
#: The version of a layout made from several examples or transformed ones (its ``sources``).
SOURCES_VERSION = 3
#: Versions this module reads: 1 had no torus and no walk fill, 2 one untransformed texture.
READABLE = (1, 2, 3)
#: What a companion map's values are, for :func:`apply_layout` (see :meth:`Layout.render`).
COMPANION_KINDS = ("blend", "hard", *NORMAL_KINDS)


def check_companion_kind(kind: str, channels: int, *, walk: bool) -> None:
    """Whether a companion map of ``channels`` channels can be rendered as ``kind`` by a layout
    (``walk``: one of walk mode's); :class:`~quilting.core.errors.LayoutError` saying why
    not. The rules of :meth:`Layout.render`, for callers that check before any work."""
    if kind not in COMPANION_KINDS:
        raise LayoutError(f"unknown companion kind {kind!r}; one of {', '.join(COMPANION_KINDS)}")
    if kind in NORMAL_KINDS and channels < 3:
        raise LayoutError(f"a {kind!r} companion needs 3 or 4 channels (x, y, z), got {channels}")
    if kind == "hard" and walk:
        raise LayoutError(
            "a walk-mode layout blends every block into its neighbours across the walk: it "
            "has no unmixed rendering for a 'hard' companion (use mode 'cut' or kind 'blend')"
        )


@dataclass
class LayoutPass:
    """One synthesis pass: a grid of blocks, where each came from and how it was cut.

    Attributes
    ----------
    grid : Grid
    positions : ndarray of int32, shape (rows, cols, 2)
        Source (y, x) of each block's top-left corner.
    cut_cols, cut_rows : ndarray of int16, shape (rows, cols, block)
        Each block's seam (see :func:`quilting.core.seams.new_block_mask`).
    cut_right, cut_bottom : ndarray of int16, shape (rows, cols, block)
        Seams against the blocks on the right and below across the wrap of a torus
        (``block``: no cut).
    feather : int or None
        None: blocks are pasted through their seams. An int: walk mode (the minimum-resistance
        cut), each block writes its whole footprint, blended across its walk cuts over
        ``feather`` pixels with the output there or the continuations of its neighbours
        (:func:`quilting.core.walk.fill_blocks`).
    blend : {'none', 'poisson'}
        How the seams were blended after each level's paste (:mod:`quilting.core.blend`);
        a blended pass is rendered in working pixels.
    """

    grid: Grid
    positions: NDArray[np.int32]
    cut_cols: NDArray[np.int16]
    cut_rows: NDArray[np.int16]
    cut_right: NDArray[np.int16]
    cut_bottom: NDArray[np.int16]
    feather: int | None = None
    blend: str = "none"

    @classmethod
    def empty(cls, grid: Grid, feather: int | None = None, blend: str = "none") -> LayoutPass:
        shape = (grid.rows, grid.cols)
        return cls(
            grid=grid,
            positions=np.zeros((*shape, 2), dtype=np.int32),
            cut_cols=np.zeros((*shape, grid.block), dtype=np.int16),
            cut_rows=np.zeros((*shape, grid.block), dtype=np.int16),
            cut_right=np.full((*shape, grid.block), grid.block, dtype=np.int16),
            cut_bottom=np.full((*shape, grid.block), grid.block, dtype=np.int16),
            feather=feather,
            blend=blend,
        )

    def fill_walk(
        self,
        source: NDArray[np.float32],
        canvas: NDArray[np.float32],
        done: Callable[[int, int], object] | None = None,
    ) -> None:
        """Write a walk pass's blocks over ``canvas`` group by group, each blended with what
        the groups before it wrote (:func:`quilting.core.walk.fill_blocks`).

        Parameters
        ----------
        source : ndarray of float32, shape (h, w, C)
            The texture in working pixels.
        canvas : ndarray of float32, shape (grid height, grid width, C), written in place
        done : callable, optional
            ``done(groups_written, groups)`` after each group.
        """
        assert self.feather is not None, "not a walk pass"
        g = self.grid
        groups = g.groups()
        for count, (rows, cols) in enumerate(groups, start=1):
            filled = fill_blocks(
                source,
                canvas,
                g,
                self.positions,
                rows,
                cols,
                self.cut_cols[rows, cols],
                self.cut_rows[rows, cols],
                self.feather,
            )
            write_blocks(canvas, filled, g.origins(rows, cols))
            if done is not None:
                done(count, len(groups))

    def to_json(self) -> dict[str, Any]:
        g = self.grid
        data: dict[str, Any] = {
            "block": g.block,
            "overlap": g.overlap,
            "rows": g.rows,
            "cols": g.cols,
            "positions": self.positions.reshape(-1, 2).tolist(),
            "cut_cols": self.cut_cols.reshape(-1, g.block).tolist(),
            "cut_rows": self.cut_rows.reshape(-1, g.block).tolist(),
        }
        if self.feather is not None:
            data["fill"] = "walk"
            data["feather"] = self.feather
        if self.blend != "none":
            data["blend"] = self.blend
        if g.wrapped:
            data["period"] = list(g.period)
            data["cut_right"] = self.cut_right.reshape(-1, g.block).tolist()
            data["cut_bottom"] = self.cut_bottom.reshape(-1, g.block).tolist()
        return data

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> LayoutPass:
        period = data.get("period", [0, 0])
        grid = Grid(
            block=int(data["block"]),
            overlap=int(data["overlap"]),
            rows=int(data["rows"]),
            cols=int(data["cols"]),
            period=(int(period[0]), int(period[1])),
        )
        if not (
            grid.block >= 1 and 0 <= grid.overlap < grid.block and grid.rows >= 1 and grid.cols >= 1
        ):
            raise LayoutError(f"layout pass has an impossible grid: {grid}")
        for wrap, count in zip(grid.period, (grid.rows, grid.cols), strict=True):
            if wrap and not 1 <= count * grid.step + grid.overlap - wrap <= grid.step:
                raise LayoutError(f"layout pass has an impossible torus: {grid}")
        shape = (grid.rows, grid.cols)
        full = np.full((*shape, grid.block), grid.block, dtype=np.int16)
        try:
            positions = np.asarray(data["positions"], dtype=np.int32).reshape(*shape, 2)
            cuts = [
                np.asarray(data[name], dtype=np.int16).reshape(*shape, grid.block)
                if name in data or name in ("cut_cols", "cut_rows")
                else full
                for name in ("cut_cols", "cut_rows", "cut_right", "cut_bottom")
            ]
        except (ValueError, OverflowError) as exc:  # OverflowError: past int16 / int32
            raise LayoutError(f"layout arrays do not match the grid {grid}: {exc}") from None
        if (positions < 0).any() or any((cut < 0).any() for cut in cuts):
            raise LayoutError("layout holds negative positions or cuts")
        if any((cut > grid.block).any() for cut in cuts):
            raise LayoutError(f"layout cuts exceed the block size {grid.block}")
        feather = None
        if data.get("fill", "paste") == "walk":
            feather = int(data.get("feather", 0))
            if feather < 0 or grid.wrapped:
                raise LayoutError("layout pass has an impossible walk fill")
        elif data.get("fill", "paste") != "paste":
            raise LayoutError(f"layout pass has an unknown fill {data.get('fill')!r}")
        blend = data.get("blend", "none")
        if blend not in BLENDS or (blend != "none" and feather is not None):
            raise LayoutError(f"layout pass has an unknown blend {blend!r}")
        cut_cols, cut_rows, cut_right, cut_bottom = cuts
        return cls(grid, positions, cut_cols, cut_rows, cut_right, cut_bottom, feather, blend)


@dataclass
class Layout:
    """Where every block of a result came from and how it was cut.

    Attributes
    ----------
    source_shape : (int, int)
        (height, width) of the texture the layout was made from (of the atlas of its
        examples when ``sources`` is set); block positions are in it.
    output_shape : (int, int)
        (height, width) of the result.
    passes : list of LayoutPass
        Rendered in order, each over the previous one.
    meta : dict
        The options and seed that produced it (informative).
    sources : SourceSet or None
        Several examples or transformed ones: which (example, transform) lies where in the
        atlas the positions refer to (:mod:`quilting.core.sources`). None: one texture as
        given.
    """

    source_shape: tuple[int, int]
    output_shape: tuple[int, int]
    passes: list[LayoutPass]
    meta: dict[str, Any] = field(default_factory=dict)
    sources: SourceSet | None = None

    def provenance(self, index: int = -1) -> dict[str, NDArray[Any]]:
        """Where each block of pass ``index`` came from, in the examples' own terms.

        Returns
        -------
        dict of str to ndarray, each of shape (rows, cols)
            ``example`` (index into the examples given), ``transform`` (index into
            :data:`quilting.core.sources.TRANSFORMS`), ``y`` and ``x`` (the block's corner in
            the example once transformed).
        """
        positions = self.passes[index].positions.astype(np.intp)
        if self.sources is None:
            zeros = np.zeros(positions.shape[:2], dtype=np.intp)
            return {"example": zeros, "transform": zeros.copy(), "y": positions[..., 0],
                    "x": positions[..., 1]}  # fmt: skip
        placement, local = self.sources.locate(positions)
        placements = self.sources.placements
        example = np.array([p.example for p in placements], dtype=np.intp)[placement]
        names = np.array([TRANSFORMS.index(p.transform) for p in placements], dtype=np.intp)
        return {"example": example, "transform": names[placement], "y": local[..., 0],
                "x": local[..., 1]}  # fmt: skip

    def render(self, source: NDArray[np.generic], kind: str = "blend") -> NDArray[np.generic]:
        """Quilt ``source`` (H, W, C) with this layout; same dtype and channels out.

        Parameters
        ----------
        source : ndarray, shape (H, W, C)
        kind : {'blend', 'hard', 'normal'}
            What the values are (:data:`COMPANION_KINDS`): 'blend' renders them as the result
            was made, seams blended where its layout blends them; 'hard' never mixes values
            (masks, material IDs): each pixel is a source pixel, from the same blocks and cuts;
            'normal' blends like 'blend', then makes the first three channels (a tangent-space
            normal, each in [0, 1] for [-1, 1]) unit vectors again where blending mixed them.

        Returns
        -------
        ndarray, shape (output height, output width, C)
        """
        walk = any(p.feather is not None for p in self.passes)
        check_companion_kind(kind, source.shape[2], walk=walk)
        blended = walk or any(p.blend != "none" for p in self.passes)
        if not blended or kind == "hard":

            def blocks(_: int, layout_pass: LayoutPass, rows: Index, cols: Index) -> Blocks:
                corners = layout_pass.positions[rows, cols].astype(np.intp)
                return gather(source, corners, layout_pass.grid.block)

            return self.compose(source.shape[2], source.dtype, blocks)
        canvas = self._walk_canvas(source) if walk else self._blended_canvas(source)
        height, width = self.output_shape
        cropped = np.ascontiguousarray(canvas[:height, :width])
        if kind in NORMAL_KINDS:
            renormalize(cropped)
        converted = from_working(cropped, source.dtype)
        return cropped.astype(source.dtype) if converted is None else converted

    def _walk_canvas(self, source: NDArray[np.generic]) -> NDArray[np.float32]:
        """The grid-sized working canvas of a walk-mode layout (blended across its cuts)."""
        (layout_pass,) = self.passes  # walk mode is a single pass of synthesis
        g = layout_pass.grid
        canvas = np.zeros((g.height, g.width, source.shape[2]), dtype=np.float32)
        layout_pass.fill_walk(to_working(source), canvas)
        return canvas

    def _blended_canvas(self, source: NDArray[np.generic]) -> NDArray[np.float32]:
        """The working canvas of a layout with blended seams, as the engine made it: each
        level pasted and then its cells blended (:func:`quilting.core.blend.blend_cells`)."""
        working = to_working(source)
        canvas: NDArray[np.float32] | None = None
        for layout_pass in self.passes:
            g = layout_pass.grid
            # Each pass starts on its own canvas, as the engine's passes do (transfer).
            canvas = np.zeros((g.height, g.width, source.shape[2]), dtype=np.float32)
            far = g.wrapped
            for rows, cols in g.groups():
                corners = g.origins(rows, cols)
                old = gather(canvas, corners, g.block, wrap=far)
                blocks = gather(working, layout_pass.positions[rows, cols].astype(np.intp), g.block)
                owned = paste(
                    canvas,
                    blocks,
                    corners,
                    layout_pass.cut_cols[rows, cols],
                    layout_pass.cut_rows[rows, cols],
                    layout_pass.cut_right[rows, cols] if far else None,
                    layout_pass.cut_bottom[rows, cols] if far else None,
                )
                if layout_pass.blend == "poisson":
                    blend_cells(canvas, old, blocks, owned, g, rows, cols)
        assert canvas is not None
        return canvas

    def compose(
        self,
        channels: int,
        dtype: npt.DTypeLike,
        blocks: Callable[[int, LayoutPass, Index, Index], Blocks],
        fill: float = 0,
        *,
        contiguous: bool = True,
    ) -> NDArray[Any]:
        """Paste blocks through the layout's seams, pass by pass and level by level.

        Parameters
        ----------
        channels, dtype
            Of the image made.
        blocks : callable
            ``blocks(pass_index, pass, rows, cols)``: the blocks placed at those grid cells,
            shape (n, B, B, channels) or broadcastable to it.
        fill
            Value of pixels no block covers (none, once a first pass covers its grid).
        contiguous
            False: the output-sized view of the grid-sized canvas, without the copy that
            makes it C-contiguous (rows keep the canvas's stride), for callers that read it
            row by row and would rather not hold the image twice.

        Returns
        -------
        ndarray, shape (output height, output width, channels)
        """
        height, width = self.output_shape
        image: NDArray[Any] | None = None
        for index, layout_pass in enumerate(self.passes):
            g = layout_pass.grid
            canvas = np.full((g.height, g.width, channels), fill, dtype=dtype)
            if image is not None:  # a later pass is synthesized over the earlier ones
                h, w = min(g.height, height), min(g.width, width)
                canvas[:h, :w] = image[:h, :w]
            far = g.wrapped
            for rows, cols in g.groups():
                if layout_pass.feather is not None:
                    _compose_walk(canvas, index, layout_pass, rows, cols, blocks)
                    continue
                paste(
                    canvas,
                    blocks(index, layout_pass, rows, cols),
                    g.origins(rows, cols),
                    layout_pass.cut_cols[rows, cols],
                    layout_pass.cut_rows[rows, cols],
                    layout_pass.cut_right[rows, cols] if far else None,
                    layout_pass.cut_bottom[rows, cols] if far else None,
                )
            image = canvas
        assert image is not None
        cropped = image[:height, :width]
        return np.ascontiguousarray(cropped) if contiguous else cropped

    def to_json(self) -> str:
        """The layout as a JSON document (see :meth:`from_json`)."""
        document: dict[str, Any] = {
            "format": FORMAT,
            "version": VERSION if self.sources is None else SOURCES_VERSION,
            "source_shape": list(self.source_shape),
            "output_shape": list(self.output_shape),
            "meta": self.meta,
            "passes": [p.to_json() for p in self.passes],
        }
        if self.sources is not None:
            document["sources"] = self.sources.to_json()
        return json.dumps(document, separators=(",", ":"))

    @classmethod
    def from_json(cls, text: str | bytes) -> Layout:
        """Parse a layout document; a malformed one raises :class:`LayoutError`."""
        try:
            data = json.loads(text)
        except (ValueError, UnicodeDecodeError) as exc:
            raise LayoutError(f"layout is not valid JSON: {exc}") from None
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise LayoutError(f'not a quilting layout (expected "format": "{FORMAT}")')
        if data.get("version") not in READABLE:
            raise LayoutError(
                f"unsupported layout version {data.get('version')!r} (this reads "
                f"{', '.join(map(str, READABLE))})"
            )
        try:
            source_shape = (int(data["source_shape"][0]), int(data["source_shape"][1]))
            output_shape = (int(data["output_shape"][0]), int(data["output_shape"][1]))
            passes = [LayoutPass.from_json(p) for p in data["passes"]]
        except LayoutError:
            raise
        # What int() and indexing raise on a value of the wrong kind ("abc", 1e400, a dict
        # where a list belongs): the document's fault, said as such, never a traceback.
        except (KeyError, TypeError, IndexError, ValueError, OverflowError, AttributeError) as exc:
            raise LayoutError(f"layout is missing or has a malformed field: {exc!r}") from None
        if not passes:
            raise LayoutError("layout has no passes")
        if min(output_shape) < 1:
            raise LayoutError(f"layout output shape {list(output_shape)} has no pixels")
        if len(passes) > 1 and any(p.feather is not None for p in passes):
            raise LayoutError("a walk fill is a layout's only pass (walk mode synthesizes once)")
        for p in passes:
            g = p.grid
            if (p.positions[..., 0] > source_shape[0] - g.block).any() or (
                p.positions[..., 1] > source_shape[1] - g.block
            ).any():
                raise LayoutError("layout positions fall outside its source")
        last = passes[-1].grid
        if output_shape[0] > last.height or output_shape[1] > last.width:
            raise LayoutError("layout output is larger than its grid covers")
        meta = data.get("meta", {})
        sources = None
        if data.get("version") == SOURCES_VERSION:
            sources = SourceSet.from_json(data.get("sources"))
            if sources.shape != source_shape:
                raise LayoutError("layout sources do not match its source_shape")
        return cls(
            source_shape, output_shape, passes, meta if isinstance(meta, dict) else {}, sources
        )

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the layout as JSON to ``path``."""
        with open(path, "w", encoding="utf-8") as handle:
            handle.write(self.to_json())

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> Layout:
        """Read a layout written by :meth:`save`."""
        try:
            with open(path, "rb") as handle:
                text = handle.read()
        except OSError as exc:
            raise LayoutError(f"cannot read layout {os.fspath(path)!r}: {exc.strerror}") from None
        return cls.from_json(text)


def write_blocks(
    canvas: NDArray[np.generic], blocks: NDArray[np.generic], corners: NDArray[np.intp]
) -> None:
    """Write whole blocks (n, B, B, C) at ``corners`` (n, 2) of ``canvas`` (H, W, C)."""
    block = blocks.shape[1]
    for k, (y, x) in enumerate(corners.tolist()):
        canvas[y : y + block, x : x + block] = blocks[k]


def _compose_walk(
    canvas: NDArray[Any],
    index: int,
    layout_pass: LayoutPass,
    rows: Index,
    cols: Index,
    blocks: Callable[[int, LayoutPass, Index, Index], Blocks],
) -> None:
    """Compose one group of a walk pass without blending: each pixel gets the value of the
    block it mostly shows, the new one or the neighbour whose continuation it is (see
    :func:`quilting.core.walk.regions`). Meant for per-block values (block indices): a
    continuation's pixels are not the neighbour's block itself; :meth:`Layout.render` renders
    images.
    """
    g = layout_pass.grid
    label = regions(
        g, rows, cols, layout_pass.cut_cols[rows, cols], layout_pass.cut_rows[rows, cols]
    )
    corners = g.origins(rows, cols)
    old = gather(canvas, corners, g.block)
    shape = old.shape
    out = np.where(
        label[..., None] == -1, old, np.broadcast_to(blocks(index, layout_pass, rows, cols), shape)
    )
    for value, (dr, dc) in ((1, (0, 1)), (2, (1, 0)), (3, (1, 1))):
        where = label == value
        if where.any():
            values = np.broadcast_to(
                blocks(index, layout_pass, np.maximum(rows - dr, 0), np.maximum(cols - dc, 0)),
                shape,
            )
            out = np.where(where[..., None], values, out)
    write_blocks(canvas, out, corners)


def renormalize(canvas: NDArray[np.float32]) -> None:
    """Make the first three channels of a working canvas (H, W, C >= 3), normal vectors
    stored as ``(n + 1) / 2``, unit length again, in place; a zero vector stays as it is."""
    vectors = canvas[..., :3] * np.float32(2) - np.float32(1)
    length = np.sqrt(np.einsum("...k,...k->...", vectors, vectors))[..., None]
    np.divide(vectors, length, out=vectors, where=length > 0)
    canvas[..., :3] = (vectors + np.float32(1)) * np.float32(0.5)


def apply_layout(layout: Layout, companion: object, *, kind: str = "blend") -> NDArray[np.generic]:
    """Quilt a companion map (normal, roughness, height...) with the layout of a result.

    Parameters
    ----------
    layout : Layout
        From ``Result.layout`` or :meth:`Layout.load`.
    companion : ndarray, shape (H, W) or (H, W, C), or a list of them
        A map of the same height and width as the texture the layout was made from; any
        accepted dtype and channel count. A layout made from several examples takes a list,
        one map per example and of its size, all of one dtype and channel count.
    kind : {'blend', 'hard', 'normal', 'normal_dx'}
        How seams treat its values when the layout blends them (``blend='poisson'`` or walk
        mode; otherwise every kind gives the same pixels): 'blend' (the default) as the
        result's pixels; 'hard' never mixed (masks, material or object IDs), each pixel one of
        the map's from the same blocks and cuts (not for walk mode, which has no unmixed
        rendering); 'normal' and 'normal_dx' blended, then the (x, y, z) channels, stored as
        ``(n + 1) / 2``, made unit vectors again. Where the layout took rotated or mirrored
        blocks (``transforms``), a normal map's vectors turn with its pixels: x and y are
        swapped and negated as the transform moves the image's axes, for y pointing up
        ('normal': OpenGL, Blender, green up) or down ('normal_dx': DirectX, green down).

    Returns
    -------
    ndarray, shape (out_h, out_w) or (out_h, out_w, C)
        Same dtype and channels as ``companion``, pixel-aligned with the result.
    """
    if layout.sources is not None:
        return _apply_sourced(layout, layout.sources, companion, kind)
    view, fmt = as_channels(companion, "companion")
    if view.shape[:2] != tuple(layout.source_shape):
        raise LayoutError(
            f"companion map is {view.shape[1]}x{view.shape[0]} (width x height) but the layout "
            f"was made from a {layout.source_shape[1]}x{layout.source_shape[0]} texture"
        )
    return fmt.restore(layout.render(view, kind))


def _apply_sourced(
    layout: Layout, sources: SourceSet, companion: object, kind: str
) -> NDArray[np.generic]:
    """:func:`apply_layout` for a layout of several or transformed examples: the companions
    laid into the atlas as the examples were, then rendered."""
    maps = list(companion) if isinstance(companion, list | tuple) else [companion]
    if len(maps) != len(sources.examples):
        raise LayoutError(
            f"this layout was made from {len(sources.examples)} example(s); got {len(maps)} "
            "companion map(s), one per example in the same order is needed"
        )
    views = []
    fmt = None
    for index, (item, shape) in enumerate(zip(maps, sources.examples, strict=True)):
        view, item_fmt = as_channels(item, f"companion {index}")
        if view.shape[:2] != shape:
            raise LayoutError(
                f"companion map {index} is {view.shape[1]}x{view.shape[0]} (width x height) "
                f"but example {index} was {shape[1]}x{shape[0]}"
            )
        if fmt is not None and (item_fmt.dtype, item_fmt.channels) != (fmt.dtype, fmt.channels):
            raise LayoutError("companion maps must all have one dtype and channel count")
        fmt = fmt or item_fmt
        views.append(view)
    assert fmt is not None
    check_companion_kind(kind, fmt.channels, walk=any(p.feather is not None for p in layout.passes))
    return fmt.restore(layout.render(sources.build(views, kind), kind))
