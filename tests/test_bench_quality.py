"""The quality benchmark's own pieces: its band/core gradient ratio, its variants and textures.

The benchmark scripts are not a package: they are loaded by path (as tests/test_docs.py loads
docs/generate.py). Nothing here needs texeval.
"""

from __future__ import annotations

import importlib.util
import sys
from collections.abc import Iterator
from fractions import Fraction
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

import quilting
from quilting.core.grid import Grid

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def _load(name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(name, BENCHMARKS / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # its dataclasses look their module up while being made
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def bench() -> Iterator[ModuleType]:
    # bench_quality imports its neighbours (benchtools, quality_textures) as top-level modules.
    sys.path.insert(0, str(BENCHMARKS))
    try:
        yield _load("bench_quality")
    finally:
        sys.path.remove(str(BENCHMARKS))


@pytest.fixture(scope="module")
def textures() -> ModuleType:
    return _load("quality_textures")


GRID = Grid.covering(100, 120, block=24, overlap=6)  # step 18


def test_the_bands_are_the_overlap_strips(bench: ModuleType) -> None:
    mask = bench.band_mask(GRID, (100, 120))
    assert mask.shape == (100, 120)
    columns = np.flatnonzero(mask.all(axis=0))
    rows = np.flatnonzero(mask.all(axis=1))
    want_cols = [x for j in range(1, GRID.cols) for x in range(18 * j, 18 * j + 6) if x < 120]
    want_rows = [y for i in range(1, GRID.rows) for y in range(18 * i, 18 * i + 6) if y < 100]
    assert columns.tolist() == want_cols
    assert rows.tolist() == want_rows
    # everything else is a core pixel
    assert not mask[
        np.ix_(np.setdiff1d(np.arange(100), rows), np.setdiff1d(np.arange(120), columns))
    ].any()


def test_a_ramp_has_a_ratio_of_exactly_one(bench: ModuleType) -> None:
    y, x = np.mgrid[0:100, 0:120]
    ramp = 0.002 * x + 0.003 * y
    assert bench.band_core_ratio(ramp, GRID) == pytest.approx(1.0, abs=1e-9)
    rgb = np.dstack([ramp, ramp, ramp]).astype(np.float32)
    assert bench.band_core_ratio(rgb, GRID) == pytest.approx(1.0, abs=1e-6)


def test_steps_planted_in_the_bands_raise_the_ratio(bench: ModuleType) -> None:
    rng = np.random.default_rng(0)
    noise = rng.uniform(0.4, 0.6, size=(100, 120))
    plain = bench.band_core_ratio(noise, GRID)
    assert plain == pytest.approx(1.0, abs=0.05)
    seamed = noise.copy()
    for j in range(1, GRID.cols):  # a step across the middle of every vertical strip
        seamed[:, 18 * j + 3 :] += 0.3 if j % 2 else -0.3
    for i in range(1, GRID.rows):
        seamed[18 * i + 3 :, :] += 0.3 if i % 2 else -0.3
    assert bench.band_core_ratio(seamed, GRID) > 1.5
    smooth = noise.copy()  # the bands blurred flat: below 1
    mask = bench.band_mask(GRID, noise.shape)
    smooth[mask] = 0.5
    assert bench.band_core_ratio(smooth, GRID) < 0.5


def test_a_flat_image_gives_nan(bench: ModuleType) -> None:
    assert np.isnan(bench.band_core_ratio(np.full((100, 120), 0.5), GRID))


def test_the_ratio_reads_a_result_s_grid(bench: ModuleType) -> None:
    texture = np.random.default_rng(1).integers(0, 256, size=(64, 64), dtype=np.uint8)
    result = quilting.synthesize(texture, (90, 90), block=24, seed=1, backend="fft")
    grid = result.layout.passes[-1].grid
    assert (grid.block, grid.overlap) == (24, 4)
    ratio = bench.band_core_ratio(result.image, grid)
    assert 0.5 < ratio < 2.0


def test_variants_parse_and_resolve_overlap_frac(bench: ModuleType) -> None:
    cut = bench.parse_variant("cut:")
    assert (cut.name, cut.options, cut.overlap_frac) == ("cut", {}, None)
    o4 = bench.parse_variant("o4:overlap_frac=1/4,tolerance=0.2,error=luminance,overlap_x=None")
    assert o4.overlap_frac == Fraction(1, 4)
    assert o4.options == {"tolerance": 0.2, "error": "luminance", "overlap_x": None}
    # Lower-case 'none' is a value of blend, not None.
    assert bench.parse_variant("plain:blend=none,x=null").options == {"blend": "none", "x": None}
    assert o4.kwargs(48)["overlap"] == 12
    assert bench.parse_variant("o6:overlap_frac=1/6").kwargs(45)["overlap"] == 8  # 7.5 half up
    for bad in (
        "",
        ":tolerance=1",
        "x:tolerance",
        "x:overlap_frac=1/2",
        "x:overlap=4,overlap_frac=0.2",
    ):
        with pytest.raises(ValueError):
            bench.parse_variant(bad)


def test_unknown_and_reserved_options_are_refused(bench: ModuleType) -> None:
    bench.check_names([bench.parse_variant("a:tolerance=0.2")], quilting.synthesize)
    bench.check_names([bench.parse_variant("a:iterations=3")], quilting.transfer)
    with pytest.raises(ValueError, match="takes no option 'no_such_option'"):
        bench.check_names([bench.parse_variant("a:no_such_option=1")], quilting.synthesize)
    with pytest.raises(ValueError, match="takes no option 'iterations'"):
        bench.check_names([bench.parse_variant("a:iterations=3")], quilting.synthesize)
    with pytest.raises(ValueError, match="set by the benchmark"):
        bench.check_names([bench.parse_variant("a:seed=3")], quilting.synthesize)
    texture = np.random.default_rng(1).integers(0, 256, size=(64, 64), dtype=np.uint8)
    with pytest.raises(ValueError, match="tolerance"):
        bench.dry_run([bench.parse_variant("t:tolerance=-1")], texture, [16])


def test_the_issue_s_block_rule(bench: ModuleType) -> None:
    assert [bench.rule_block(np.zeros((s, s))) for s in (30, 60, 136, 192, 256)] == [
        16,
        20,
        45,
        48,
        48,
    ]


def test_procedural_textures_are_deterministic(textures: ModuleType) -> None:
    names = textures.procedural_names()
    assert len(names) >= 10
    kinds = set()
    for name in names:
        first = textures.generate(name)
        again = textures.generate(name)
        assert first.dtype == np.uint8
        assert first.shape[:2] in ((192, 192), (256, 256))
        assert first.ndim == 2 or first.shape[2] == 3
        assert first.tobytes() == again.tobytes(), name
        assert first.std() > 10, f"{name} is nearly flat"
        kinds.add(first.ndim)
    assert kinds == {2, 3}  # gray and RGB


def test_photos_are_the_textures_of_the_repository(textures: ModuleType) -> None:
    photos = textures.photos()
    assert {"brick", "gravel", "hubble", "wood"} <= set(photos)
    assert not any(n.startswith("target_") or n in ("camera", "cat") for n in photos)
    assert "cloud_rgba" not in photos
    assert all(path.is_file() for path in photos.values())


def test_edge_runs_count_straight_cuts_along_a_band_edge(bench: ModuleType) -> None:
    texture = np.random.default_rng(2).integers(0, 256, size=(64, 64), dtype=np.uint8)
    result = quilting.synthesize(texture, (90, 90), block=24, seed=1, backend="fft")
    layout_pass = result.layout.passes[-1]
    assert 0 <= bench.edge_runs(layout_pass) < 1
    overlap = layout_pass.grid.overlap
    for value, expected in ((0, 1.0), (overlap - 1, 1.0), (1, 0.0)):
        layout_pass.cut_cols[...] = value
        layout_pass.cut_rows[...] = value
        assert bench.edge_runs(layout_pass) == expected
    # A run shorter than the shortest counted: alternate the edge every 4 pixels.
    layout_pass.cut_cols[...] = (np.arange(24) // 4 % 2) * (overlap - 1)
    layout_pass.cut_rows[...] = (np.arange(24) // 4 % 2) * (overlap - 1)
    assert bench.edge_runs(layout_pass, shortest=5) == 0.0
    assert bench.edge_runs(layout_pass, shortest=4) > 0.9
