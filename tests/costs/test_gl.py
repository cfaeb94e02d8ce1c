"""The ``gl`` backend: GLSL compute shaders through moderngl, against ``reference`` and ``fft``.

Every test carries the ``gl`` marker; those that need a context get it through the ``gl`` and
``gl_info`` fixtures of tests/conftest.py: without an OpenGL 4.3 context they skip, and in CI
(``QUILTING_REQUIRE_GL``) a skip is a failure. Mesa llvmpipe runs these shaders 20-40x slower
than ``fft`` computes the same fields, so every input here is small.
"""

from __future__ import annotations

import dataclasses
import importlib.resources
import itertools
import os
import re
import subprocess
import sys
import threading
import xml.etree.ElementTree as ET
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray

import quilting
from quilting.core.errors import BackendError, InvalidParameterError
from quilting.core.fields import CostRequest, ExactScorer, FieldBatch, Shortlist
from quilting.core.grid import Grid, Overlap
from quilting.core.select import acceptable, kth_smallest
from quilting.costs import registry
from quilting.costs.fallback import FallbackBackend
from quilting.costs.fft import FFTBackend
from quilting.costs.reference import ReferenceBackend

pytestmark = pytest.mark.gl

TESTS = Path(__file__).resolve().parents[1]
TEXTURES = TESTS / "data"

Array = NDArray[np.float32]


# --------------------------------------------------------------------------------------------
# Helpers
# --------------------------------------------------------------------------------------------


def _masks(rng: np.random.Generator, block: int) -> list[Array]:
    """The engine's three overlap masks and a weighted mask with holes and an empty row."""
    overlap = max(1, min(block // 5, (block - 1) // 2))
    grid = Grid(block=block, overlap=overlap, rows=2, cols=2)
    masks = [grid.overlap_mask(kind) for kind in (Overlap.LEFT, Overlap.TOP, Overlap.BOTH)]
    weighted = (rng.random((block, block)) < 0.4) * rng.uniform(0.1, 2.0, (block, block))
    weighted[block // 2] = 0  # a row without a single weight: the kernel's empty span
    weighted[0, 0] = 1.5  # never all zero, even for block 3
    masks.append(weighted.astype(np.float32))
    return masks


def _plain_requests(rng: np.random.Generator, block: int, channels: int) -> list[CostRequest]:
    return [
        CostRequest(rng.random((block, block, channels), dtype=np.float32), mask)
        for mask in _masks(rng, block)
    ]


def _transfer_requests(
    rng: np.random.Generator, block: int, channels: int, guide_channels: int
) -> list[CostRequest]:
    """Every mask with every combination of the transfer terms, zero weights included."""
    out = []
    for mask in _masks(rng, block):
        template = rng.random((block, block, channels), dtype=np.float32)
        previous = rng.random((block, block, channels), dtype=np.float32)
        guide = rng.random((block, block, guide_channels), dtype=np.float32)
        out += [
            CostRequest(template, mask, previous, 0.3, guide, 0.7),
            CostRequest(template, mask, previous, 1.25),
            CostRequest(template, mask, guide=guide, guide_weight=2.0),
            CostRequest(template, mask),
            CostRequest(template, mask, previous, 0.0, guide, 0.0),
        ]
    return out


def _run_fields(
    backend: Any,
    source: Array,
    block: int,
    requests: Sequence[CostRequest],
    guide: Array | None = None,
) -> tuple[FieldBatch, FieldBatch]:
    """The backend's fields and the reference's, after checking the declared bound holds."""
    backend.prepare(source, block, guide)
    ref = ReferenceBackend()
    ref.prepare(source, block, guide)
    got, want = backend.fields(requests), ref.fields(requests)
    backend.close()
    shape = (len(requests), source.shape[0] - block + 1, source.shape[1] - block + 1)
    assert got.values.shape == want.values.shape == shape
    assert got.values.dtype == np.float32
    assert got.error_bound.shape == (len(requests),)
    error = np.abs(got.values.astype(np.float64) - want.values).max(axis=(1, 2))
    assert np.all(error <= got.error_bound), (error, got.error_bound)
    return got, want


def _assert_tight(got: FieldBatch, want: FieldBatch) -> None:
    # A bound is only useful if it is far below the spread of the costs it must separate.
    spread = want.values.max(axis=(1, 2)) - want.values.min(axis=(1, 2))
    assert np.all(spread > 0)
    assert np.all(got.error_bound < 1e-2 * spread), (got.error_bound, spread)


def _texture(name: str, size: int = 96) -> NDArray[np.uint8]:
    image = quilting.read_image(TEXTURES / f"{name}.png")
    return np.ascontiguousarray(image[:size, :size])


def _as_float(image: NDArray[np.uint8]) -> Array:
    image = image[..., None] if image.ndim == 2 else image
    return (image.astype(np.float32) / 255).astype(np.float32)


def _pieces(
    source: Array, block: int, rng: np.random.Generator
) -> tuple[list[CostRequest], list[tuple[int, int]]]:
    """Templates cut from the source itself (each has an exact zero-cost candidate)."""
    grid = Grid(block=block, overlap=max(1, block // 6), rows=2, cols=2)
    requests, corners = [], []
    for kind in (Overlap.LEFT, Overlap.TOP, Overlap.BOTH):
        y, x = (int(v) for v in rng.integers(0, source.shape[0] - block + 1, size=2))
        piece = source[y : y + block, x : x + block].copy()
        requests.append(CostRequest(piece, grid.overlap_mask(kind)))
        corners.append((y, x))
    return requests, corners


def _exact(
    source: Array, block: int, requests: Sequence[CostRequest]
) -> Callable[[NDArray[np.intp], NDArray[np.intp]], NDArray[np.float64]]:
    """``exact(owner, flat_index)`` as the engine builds it for :func:`acceptable`."""
    scorer = ExactScorer(source, block)
    field_width = source.shape[1] - block + 1

    def exact(owner: NDArray[np.intp], index: NDArray[np.intp]) -> NDArray[np.float64]:
        ys, xs = np.divmod(index, field_width)
        return scorer.costs_batch(requests, owner, ys, xs)

    return exact


def _same_shortlists(a: Sequence[Shortlist], b: Sequence[Shortlist]) -> None:
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x.index, y.index)
        np.testing.assert_array_equal(x.values, y.values)
        assert x.bound == y.bound


# --------------------------------------------------------------------------------------------
# CI: the context must exist; a skipped GL test fails
# --------------------------------------------------------------------------------------------


def _gl_required() -> bool:
    # The same rule as tests/conftest.py's gl_required().
    return os.environ.get("QUILTING_REQUIRE_GL", "").strip() not in ("", "0")


@pytest.mark.skipif(not _gl_required(), reason="QUILTING_REQUIRE_GL is not set (not CI)")
def test_ci_has_a_gl_context() -> None:
    # Not through the fixture: this asks the backend itself, so CI fails with its reason.
    from quilting.costs import gl

    info = gl.probe()
    assert info.renderer
    assert info.limits["max_ssbo_bytes"] > 0


_INNER_TESTS = """
import pytest

@pytest.mark.gl
def test_gl_skips_another_way():
    pytest.skip("some other reason")

def test_plain_skip():
    pytest.skip("not a GL test")

@pytest.mark.gl
@pytest.mark.xfail(strict=True, reason="a known bug")
def test_gl_expected_failure():
    assert False

@pytest.mark.gl
def test_gl_without_context(gl_info):
    pass
"""


def _inner_outcomes(tmp_path: Path, require: str | None) -> dict[str, tuple[str, str]]:
    """Run a small suite under this conftest in a fresh pytest: (outcome, message) per test."""
    tmp_path.mkdir()
    (tmp_path / "conftest.py").write_text((TESTS / "conftest.py").read_text())
    (tmp_path / "test_inner.py").write_text(_INNER_TESTS)
    env = {k: v for k, v in os.environ.items() if k != "QUILTING_REQUIRE_GL"}
    env["QUILTING_GL_DEVICE"] = "not-a-device"  # probe() fails: no context
    env["PYTEST_DISABLE_PLUGIN_AUTOLOAD"] = "1"  # fast: the inner suite needs no plugins
    if require is not None:
        env["QUILTING_REQUIRE_GL"] = require
    report = tmp_path / "report.xml"
    subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--rootdir",
         str(tmp_path), f"--junitxml={report}", str(tmp_path)],
        cwd=tmp_path, env=env, capture_output=True, check=False, timeout=120,
    )  # fmt: skip
    outcomes: dict[str, tuple[str, str]] = {}
    for case in ET.parse(report).getroot().iter("testcase"):
        found = [child for child in case if child.tag in ("failure", "error", "skipped")]
        assert len(found) <= 1
        if not found:
            outcomes[case.get("name", "")] = ("passed", "")
            continue
        kind = found[0].tag
        if kind == "skipped" and found[0].get("type") == "pytest.xfail":
            kind = "xfail"
        outcomes[case.get("name", "")] = (kind, found[0].get("message", ""))
    return outcomes


def test_skipped_gl_tests_fail_in_ci(tmp_path: Path) -> None:
    local = _inner_outcomes(tmp_path / "local", None)
    assert {name: kind for name, (kind, _) in local.items()} == {
        "test_gl_skips_another_way": "skipped",
        "test_plain_skip": "skipped",
        "test_gl_expected_failure": "xfail",
        "test_gl_without_context": "skipped",
    }
    assert "QUILTING_GL_DEVICE" in local["test_gl_without_context"][1]  # the reason is shown
    ci = _inner_outcomes(tmp_path / "ci", "1")
    assert {name: kind for name, (kind, _) in ci.items()} == {
        "test_gl_skips_another_way": "failure",  # turned into a failure by the hook
        "test_plain_skip": "skipped",
        "test_gl_expected_failure": "xfail",
        "test_gl_without_context": "error",  # failed in setup, by the gl_info fixture
    }
    assert "some other reason" in ci["test_gl_skips_another_way"][1]
    assert "QUILTING_REQUIRE_GL is set but" in ci["test_gl_without_context"][1]
    assert "QUILTING_GL_DEVICE" in ci["test_gl_without_context"][1]


# --------------------------------------------------------------------------------------------
# Shaders compile, in every variant the backend can ask for
# --------------------------------------------------------------------------------------------


def _variants(gl: Any) -> dict[str, list[dict[str, int]]]:
    return {
        "cost_field.comp": [
            {
                "BLOCK": block,
                "CHANNELS": channels,
                "GUIDE_CHANNELS": guide,
                "HAS_PREVIOUS": previous,
                "RUN": gl.RUN,
                "LOCAL_X": gl.LOCAL_X,
                "LOCAL_Y": gl.LOCAL_Y,
            }
            for block, channels, guide, previous in itertools.product(
                (3, 48), (1, 3, 4), range(5), (0, 1)
            )
        ],
        "kth_bound.comp": [{"LOCAL_X": gl.LOCAL_REDUCE}],
        "shortlist.comp": [{"LOCAL_X": gl.LOCAL_REDUCE}],
    }


def test_every_shader_compiles(gl: Any) -> None:
    files = sorted(
        entry.name
        for entry in importlib.resources.files("quilting.shaders").iterdir()
        if entry.name.endswith(".comp")
    )
    assert files == sorted(gl.SHADERS)
    variants = _variants(gl)
    assert sorted(variants) == files
    owner = gl._owner(gl.device_index())

    def compile_and_release(source: str) -> Callable[[Any], bool]:
        def call(ctx: Any) -> bool:
            program = ctx.compute_shader(source)
            program.release()
            return bool(ctx.error == "GL_NO_ERROR")

        return call

    for name in files:
        for defines in variants[name]:
            assert owner.run(compile_and_release(gl.shader_source(name, defines))), defines


def test_compiled_variants_are_the_ones_the_backend_uses(gl: Any, monkeypatch) -> None:
    # The table above must name exactly the defines the backend injects, with values in range.
    seen: list[tuple[str, dict[str, int]]] = []
    original = gl.GLBackend._program

    def spy(self: Any, ctx: Any, name: str, defines: dict[str, int]) -> Any:
        seen.append((name, dict(defines)))
        return original(self, ctx, name, defines)

    monkeypatch.setattr(gl.GLBackend, "_program", spy)
    rng = np.random.default_rng(1)
    source = rng.random((20, 22, 3), dtype=np.float32)
    guide_map = rng.random((20, 22, 2), dtype=np.float32)
    backend = gl.GLBackend()
    backend.prepare(source, 5, guide_map)
    requests = _transfer_requests(rng, 5, 3, 2)
    backend.fields(requests)
    backend.shortlists(requests[3:4], 0.1, 3)
    backend.close()
    variants = _variants(gl)
    names = {name for name, _ in seen}
    assert names == set(gl.SHADERS)
    for name, defines in seen:
        keys = [sorted(v) for v in variants[name]]
        assert sorted(defines) in keys, (name, defines)
        if name == "cost_field.comp":
            assert defines["CHANNELS"] == 3
            assert defines["GUIDE_CHANNELS"] in (0, 2)
            assert defines["HAS_PREVIOUS"] in (0, 1)
    assert {d["HAS_PREVIOUS"] for n, d in seen if n == "cost_field.comp"} == {0, 1}
    assert {d["GUIDE_CHANNELS"] for n, d in seen if n == "cost_field.comp"} == {0, 2}


def test_a_broken_shader_is_a_backend_error(gl: Any, monkeypatch) -> None:
    original = gl.shader_source
    monkeypatch.setattr(gl, "shader_source", lambda name, defines: "#version 430\nvoid main(")
    backend = gl.GLBackend()
    with pytest.raises(BackendError, match=r"broken\.comp did not compile"):
        backend._owner.run(lambda ctx: backend._program(ctx, "broken.comp", {"X": 1}))

    # The same through fields(): a work-group shape no other test uses, so it is compiled here.
    monkeypatch.setattr(gl, "LOCAL_Y", 2)
    rng = np.random.default_rng(2)
    source = rng.random((21, 27, 3), dtype=np.float32)
    requests = _plain_requests(rng, 6, 3)
    backend.prepare(source, 6)
    with pytest.raises(BackendError, match=r"cost_field\.comp did not compile"):
        backend.fields(requests)
    backend.close()

    # Nothing is left behind: the real source in that shape computes correct fields.
    monkeypatch.setattr(gl, "shader_source", original)
    _run_fields(gl.GLBackend(), source, 6, requests)


# --------------------------------------------------------------------------------------------
# Fields equal the reference within the declared bound
# --------------------------------------------------------------------------------------------

#: (height, width, block): field widths not a multiple of RUN, below RUN, exactly RUN and
#: 2 RUN, a one-row field, block 3 and a large block (checked against gl.RUN below).
SHAPES = [(33, 45, 3), (23, 14, 10), (14, 22, 14), (30, 24, 9), (19, 10, 3), (56, 60, 40)]


def test_shapes_cover_the_run_edges(gl: Any) -> None:
    widths = [w - b + 1 for _, w, b in SHAPES]
    assert any(w < gl.RUN for w in widths)
    assert any(w % gl.RUN == 0 for w in widths)
    assert any(w > gl.RUN and w % gl.RUN for w in widths)
    assert any(h - b + 1 == 1 for h, _, b in SHAPES)
    assert {3, 40} <= {b for _, _, b in SHAPES}


@pytest.mark.parametrize("channels", [1, 3, 4])
@pytest.mark.parametrize("shape", SHAPES, ids=lambda s: "x".join(map(str, s)))
def test_fields_equal_reference(gl: Any, channels: int, shape: tuple[int, int, int]) -> None:
    height, width, block = shape
    rng = np.random.default_rng(height * 100 + width + channels)
    source = rng.random((height, width, channels), dtype=np.float32)
    got, want = _run_fields(gl.GLBackend(), source, block, _plain_requests(rng, block, channels))
    _assert_tight(got, want)


@pytest.mark.parametrize("channels", [1, 3, 4])
@pytest.mark.parametrize("guide_channels", [1, 2, 3, 4])
def test_transfer_terms_equal_reference(gl: Any, channels: int, guide_channels: int) -> None:
    rng = np.random.default_rng(10 * channels + guide_channels)
    shape, block = (27, 34), 7
    source = rng.random((*shape, channels), dtype=np.float32)
    guide_map = rng.random((*shape, guide_channels), dtype=np.float32)
    requests = _transfer_requests(rng, block, channels, guide_channels)
    got, want = _run_fields(gl.GLBackend(), source, block, requests, guide_map)
    _assert_tight(got, want)
    # Batches with one kind of term only (another shader variant each), and none at all.
    for keep in (
        lambda r: r.previous_weight > 0 and r.guide_weight == 0,
        lambda r: r.guide_weight > 0 and r.previous_weight == 0,
        lambda r: r.previous_weight == 0 and r.guide_weight == 0,
    ):
        part = [r for r in requests if keep(r)]
        assert part
        _run_fields(gl.GLBackend(), source, block, part, guide_map)


def test_fields_of_many_blocks_at_once(gl: Any) -> None:
    # A whole level's batch: 40 blocks sharing a handful of masks (the mask cache by value).
    rng = np.random.default_rng(12)
    source = rng.random((40, 44, 3), dtype=np.float32)
    requests = [
        CostRequest(rng.random((9, 9, 3), dtype=np.float32), mask.copy())
        for mask in _masks(rng, 9) * 10
    ]
    got, want = _run_fields(gl.GLBackend(), source, 9, requests)
    _assert_tight(got, want)


@pytest.mark.parametrize("name,block", [("hubble", 48), ("gravel", 32), ("cloud_rgba", 24)])
def test_texture_pieces_have_an_exact_zero(gl: Any, name: str, block: int) -> None:
    source = _as_float(_texture(name, 128))
    requests, corners = _pieces(source, block, np.random.default_rng(5))
    got, _ = _run_fields(gl.GLBackend(), source, block, requests)
    for k, (y, x) in enumerate(corners):
        assert got.values[k, y, x] == 0.0
        assert got.values[k].min() == 0.0


def test_no_requests_no_fields(gl: Any) -> None:
    backend = gl.GLBackend()
    backend.prepare(np.zeros((10, 12, 3), np.float32), 4)
    got = backend.fields([])
    assert got.values.shape == (0, 7, 9)
    assert got.error_bound.shape == (0,)
    assert backend.shortlists([], 0.1, 3) == []
    backend.close()


# --------------------------------------------------------------------------------------------
# Shortlists: the same acceptable sets as the dense reference
# --------------------------------------------------------------------------------------------

TOLERANCES = (0.0, 0.1, 0.5)


def _inputs(kind: str) -> tuple[Array, int, list[CostRequest]]:
    rng = np.random.default_rng(len(kind))
    if kind == "random":
        source = rng.random((37, 45, 3), dtype=np.float32)
        return source, 8, _plain_requests(rng, 8, 3)
    if kind == "texture":
        source = _as_float(_texture("wood", 64))
        requests, _ = _pieces(source, 16, rng)
        return source, 16, requests + _plain_requests(rng, 16, 3)[:2]
    # A periodic source: whole families of exact zeros and exact ties.
    source = np.tile(rng.random((6, 7, 1), dtype=np.float32), (7, 7, 1))
    requests, _ = _pieces(source, 10, rng)
    return source, 10, requests


def _check_shortlists(
    backend: Any,
    source: Array,
    block: int,
    requests: Sequence[CostRequest],
    tolerance: float,
    k: int,
) -> list[Shortlist]:
    """Everything the Shortlist contract promises, and the reference's acceptable sets."""
    got = backend.shortlists(requests, tolerance, k)
    dense = backend.fields(requests).values.astype(np.float64)
    ref = ReferenceBackend()
    ref.prepare(source, block)
    exact_fields = ref.fields(requests).values
    want = ref.shortlists(requests, tolerance, k)
    exact = _exact(source, block, requests)
    field_size = exact_fields[0].size
    assert len(got) == len(requests)
    for b, listed in enumerate(got):
        context = (b, tolerance, k)
        assert listed.index.dtype == np.intp
        assert np.all(np.diff(listed.index) > 0), context  # sorted, no duplicates
        assert listed.index.size >= min(k, field_size), context
        assert np.all((listed.index >= 0) & (listed.index < field_size))
        # The values are the field's (same kernel, same inputs) and within the bound.
        np.testing.assert_array_equal(listed.values, dense[b].ravel()[listed.index])
        errors = np.abs(listed.values - exact_fields[b].ravel()[listed.index])
        assert np.all(errors <= listed.bound), context
        # Complete: every candidate the dense reduction with this bound would list, and every
        # candidate the exact costs make acceptable.
        flat = dense[b].ravel()
        top = (1 + tolerance) * (kth_smallest(flat, k) + listed.bound) + listed.bound
        assert np.isin(np.flatnonzero(flat <= top), listed.index).all(), context
        exact_flat = exact_fields[b].ravel()
        accepted = np.flatnonzero(exact_flat <= (1 + tolerance) * kth_smallest(exact_flat, k))
        assert np.isin(accepted, listed.index).all(), context
    chosen = acceptable(got, exact, tolerance, k)
    expected = acceptable(want, exact, tolerance, k)
    for b, (c, e) in enumerate(zip(chosen, expected, strict=True)):
        np.testing.assert_array_equal(c, e, err_msg=f"block {b}, tol {tolerance}, k {k}")
    return got


@pytest.mark.parametrize("kind", ["random", "texture", "periodic"])
def test_shortlists_select_like_the_reference(gl: Any, kind: str) -> None:
    source, block, requests = _inputs(kind)
    field_size = (source.shape[0] - block + 1) * (source.shape[1] - block + 1)
    backend = gl.GLBackend()
    backend.prepare(source, block)
    for tolerance, k in itertools.product(TOLERANCES, (1, 3, 50, field_size + 7)):
        _check_shortlists(backend, source, block, requests, tolerance, k)
    backend.close()


@pytest.mark.parametrize("kind", ["random", "periodic"])
def test_shortlist_overflow_reads_the_dense_field(gl: Any, monkeypatch, kind: str) -> None:
    source, block, requests = _inputs(kind)
    backend = gl.GLBackend()
    backend.prepare(source, block)
    normal = {(t, k): backend.shortlists(requests, t, k) for t in TOLERANCES for k in (1, 3, 50)}
    reduced: list[int] = []
    original = gl.shortlist_fields

    def spy(fields: NDArray[np.floating], *args: Any) -> list[Shortlist]:
        reduced.append(fields.shape[0])
        return list(original(fields, *args))

    monkeypatch.setattr(gl, "shortlist_fields", spy)
    exact = _exact(source, block, requests)
    for (tolerance, k), before in normal.items():
        want = acceptable(before, exact, tolerance, k)
        # Without overflow the GPU appended exactly the listed entries.
        total = sum(listed.index.size for listed in before)
        for entries in (0, total - 1, total):
            monkeypatch.setattr(gl, "MAX_ENTRIES", entries)
            calls = len(reduced)
            got = _check_shortlists(backend, source, block, requests, tolerance, k)
            assert len(reduced) == calls + (total > entries), (tolerance, k, entries)
            if total <= entries:
                _same_shortlists(got, before)
            for a, b in zip(acceptable(got, exact, tolerance, k), want, strict=True):
                np.testing.assert_array_equal(a, b)
    backend.close()


@pytest.mark.parametrize("limit", ["field_bytes", "groups_z"])
def test_chunked_levels_give_identical_results(gl: Any, monkeypatch, limit: str) -> None:
    rng = np.random.default_rng(9)
    source = rng.random((29, 33, 3), dtype=np.float32)
    block = 7
    requests = _plain_requests(rng, block, 3) + _plain_requests(rng, block, 3)[:3]  # 7
    whole = gl.GLBackend()
    whole.prepare(source, block)
    want_fields = whole.fields(requests)
    want_lists = whole.shortlists(requests, 0.1, 3)
    whole.close()

    backend = gl.GLBackend()
    per_request = (source.shape[0] - block + 1) * (source.shape[1] - block + 1) * 4
    if limit == "field_bytes":
        monkeypatch.setattr(gl, "MAX_FIELD_BYTES", 2 * per_request + 3)
    else:
        limits = {**backend.info.limits, "max_groups": (*backend.info.limits["max_groups"][:2], 2)}
        monkeypatch.setattr(backend, "info", dataclasses.replace(backend.info, limits=limits))
    dispatches = _count_dispatches(backend, monkeypatch)
    backend.prepare(source, block)
    got_fields = backend.fields(requests)
    assert dispatches == [2, 2, 2, 1]
    got_lists = backend.shortlists(requests, 0.1, 3)
    assert dispatches == [2, 2, 2, 1] * 2
    backend.close()
    np.testing.assert_array_equal(got_fields.values, want_fields.values)
    np.testing.assert_array_equal(got_fields.error_bound, want_fields.error_bound)
    _same_shortlists(got_lists, want_lists)


# --------------------------------------------------------------------------------------------
# Synthesis: byte-identical to fft
# --------------------------------------------------------------------------------------------

SYNTHESIS = [
    ("brick", 24, 1),
    ("grass", 32, 2),
    ("gravel", 28, 3),
    ("hubble", 24, 4),
    ("wood", 32, 5),
    ("cloud_rgba", 24, 6),
]


@pytest.mark.parametrize("mode", ["cut", "overlap"])
@pytest.mark.parametrize("name,block,seed", SYNTHESIS, ids=[s[0] for s in SYNTHESIS])
def test_synthesis_equals_fft(gl_info: Any, name: str, block: int, seed: int, mode: str) -> None:
    texture = _texture(name)
    options: dict[str, Any] = {"block": block, "mode": mode, "seed": seed}
    want = quilting.synthesize(texture, (160, 160), backend="fft", **options)
    got = quilting.synthesize(texture, (160, 160), backend="gl", **options)
    one_by_one = quilting.synthesize(texture, (160, 160), backend="gl", max_batch=1, **options)
    assert got.image.dtype == want.image.dtype == texture.dtype
    assert got.image.shape == want.image.shape == (160, 160, *texture.shape[2:])
    assert got.image.tobytes() == want.image.tobytes()
    assert one_by_one.image.tobytes() == want.image.tobytes()
    assert got.layout.passes[0].positions.tolist() == want.layout.passes[0].positions.tolist()
    for result in (got, one_by_one):
        assert result.backend == "gl"
        assert result.renderer == gl_info.renderer
        assert result.fallback is None
    assert want.backend == "fft" and want.renderer == "cpu"


# --------------------------------------------------------------------------------------------
# Limits, failures, the fallback of auto
# --------------------------------------------------------------------------------------------


def _limited(backend: Any, monkeypatch, **limits: Any) -> None:
    """Give one backend instance other device limits (the shared context keeps its own)."""
    info = dataclasses.replace(backend.info, limits={**backend.info.limits, **limits})
    monkeypatch.setattr(backend, "info", info)


def test_a_texture_over_the_buffer_limit(gl: Any, monkeypatch) -> None:
    backend = gl.GLBackend()
    _limited(backend, monkeypatch, max_ssbo_bytes=1 << 20)
    with pytest.raises(BackendError, match=r"texture \(512x512, 4 channels.*storage-buffer limit"):
        backend.prepare(np.zeros((512, 512, 4), np.float32), 16)
    with pytest.raises(BackendError, match=r"guide map .*storage-buffer limit of 1 MiB"):
        backend.prepare(
            np.zeros((512, 512, 1), np.float32), 16, np.zeros((512, 512, 2), np.float32)
        )
    monkeypatch.setattr(gl, "MAX_FIELD_BYTES", 1 << 16)
    with pytest.raises(BackendError, match=r"one cost field \(241x241 candidates\)"):
        backend.prepare(np.zeros((256, 256, 1), np.float32), 16)


def test_a_dispatch_over_the_work_group_limit(gl: Any, monkeypatch) -> None:
    rng = np.random.default_rng(4)
    source = rng.random((40, 40, 1), dtype=np.float32)
    requests = _plain_requests(rng, 6, 1)
    backend = gl.GLBackend()
    _limited(backend, monkeypatch, max_groups=(1, 1, 65535))
    backend.prepare(source, 6)
    with pytest.raises(BackendError, match="work groups exceeds this GPU's limit"):
        backend.fields(requests)
    with pytest.raises(BackendError, match="work groups exceeds this GPU's limit"):
        backend.shortlists(requests, 0.1, 3)
    # The context is fine afterwards.
    _run_fields(gl.GLBackend(), source, 6, requests)


def test_a_backend_recovers_from_a_failed_dispatch(gl: Any, monkeypatch) -> None:
    rng = np.random.default_rng(6)
    source = rng.random((30, 30, 3), dtype=np.float32)
    first, second = _plain_requests(rng, 8, 3)[:2]
    backend = gl.GLBackend()
    good = backend.info
    backend.prepare(source, 8)
    backend.fields([first])
    _limited(backend, monkeypatch, max_groups=(1, 1, 65535))
    with pytest.raises(BackendError):
        backend.fields([second])  # a new mask, refused before it reached the GPU
    monkeypatch.setattr(backend, "info", good)
    got = backend.fields([second])
    ref = ReferenceBackend()
    ref.prepare(source, 8)
    want = ref.fields([second])
    assert np.all(np.abs(got.values - want.values).max(axis=(1, 2)) <= got.error_bound)


def test_synthesize_by_name_raises_at_the_limit(gl_info: Any, monkeypatch) -> None:
    # Every backend shares the context's limits: lower them for this test only.
    monkeypatch.setitem(gl_info.limits, "max_ssbo_bytes", 1 << 20)
    texture = np.random.default_rng(0).integers(0, 256, (600, 600), dtype=np.uint8)
    with pytest.raises(BackendError, match="storage-buffer limit of 1 MiB"):
        quilting.synthesize(texture, (100, 100), block=32, backend="gl")


def test_the_device_limits_are_read(gl_info: Any) -> None:
    limits = gl_info.limits
    assert limits["max_ssbo_bytes"] >= 1 << 24  # GL 4.3 guarantees 16 MiB
    assert limits["max_shared_bytes"] >= 32768  # and 32 KiB of shared memory
    assert len(limits["max_group_size"]) == 3 and min(limits["max_group_size"]) >= 64
    assert limits["max_invocations"] >= 1024


def _fields_and_lists(
    backend: Any, source: Array, block: int, requests: Sequence[CostRequest], guide: Any = None
) -> tuple[FieldBatch, list[Shortlist]]:
    backend.prepare(source, block, guide)
    fields = backend.fields(requests)
    lists = backend.shortlists(requests, 0.1, 3)
    backend.close()
    return fields, lists


def _count_dispatches(backend: Any, monkeypatch) -> list[int]:
    """The batch size of every dispatch the backend makes from now on."""
    sizes: list[int] = []
    original = backend._dispatch

    def counting(ctx: Any, staged: Any, select: Any) -> Any:
        sizes.append(staged.n)
        return original(ctx, staged, select)

    monkeypatch.setattr(backend, "_dispatch", counting)
    return sizes


def test_inputs_over_the_buffer_limit_split_the_level(gl: Any, monkeypatch) -> None:
    # Large blocks on a small source: the templates (and previous passes, guides), not the
    # field, are what a level's buffers must hold; they are split to the device's limit.
    rng = np.random.default_rng(21)
    source = rng.random((20, 20, 4), dtype=np.float32)
    guide_map = rng.random((20, 20, 2), dtype=np.float32)
    block = 16
    requests = _transfer_requests(rng, block, 4, 2)  # 20 requests
    want_fields, want_lists = _fields_and_lists(gl.GLBackend(), source, block, requests, guide_map)
    backend = gl.GLBackend()
    template_bytes = block * block * 4 * 4
    _limited(backend, monkeypatch, max_ssbo_bytes=2 * template_bytes + 8)
    sizes = _count_dispatches(backend, monkeypatch)
    got_fields, got_lists = _fields_and_lists(backend, source, block, requests, guide_map)
    assert sizes == [2] * 20  # ten for the fields, ten for the shortlists
    np.testing.assert_array_equal(got_fields.values, want_fields.values)
    np.testing.assert_array_equal(got_fields.error_bound, want_fields.error_bound)
    _same_shortlists(got_lists, want_lists)


def test_a_mask_table_over_the_buffer_limit(gl: Any, monkeypatch) -> None:
    rng = np.random.default_rng(22)
    source = rng.random((20, 20, 1), dtype=np.float32)
    requests = _plain_requests(rng, 16, 1)
    backend = gl.GLBackend()
    _limited(backend, monkeypatch, max_ssbo_bytes=2 * 16 * 16 * 4 + 100)  # two masks
    backend.prepare(source, 16)
    first = backend.fields(requests[:2])
    with pytest.raises(BackendError, match=r"3 distinct overlap masks .*storage-buffer limit"):
        backend.fields(requests[:3])
    # Refused before anything was recorded or sent: the first two masks still work.
    again = backend.fields(requests[:2])
    np.testing.assert_array_equal(again.values, first.values)
    ref = ReferenceBackend()
    ref.prepare(source, 16)
    want = ref.fields(requests[:2])
    assert np.all(np.abs(first.values - want.values).max(axis=(1, 2)) <= first.error_bound)
    backend.close()


def test_small_work_groups_give_identical_results(gl: Any, monkeypatch) -> None:
    # A device that allows few invocations per work group gets smaller groups, same bytes.
    rng = np.random.default_rng(23)
    source = rng.random((31, 37, 3), dtype=np.float32)
    requests = _plain_requests(rng, 7, 3)
    want = _fields_and_lists(gl.GLBackend(), source, 7, requests)
    for invocations, size in ((8, (4, 4, 4)), (1, (1, 1, 1)), (64, (64, 2, 64))):
        backend = gl.GLBackend()
        _limited(backend, monkeypatch, max_invocations=invocations, max_group_size=size)
        x, y = backend._cost_group()
        assert x * y <= invocations and x <= size[0] and y <= size[1]
        assert backend._reduce_group() <= min(invocations, size[0])
        got = _fields_and_lists(backend, source, 7, requests)
        np.testing.assert_array_equal(got[0].values, want[0].values)
        _same_shortlists(got[1], want[1])


def test_too_little_shared_memory_is_a_clear_error(gl: Any, monkeypatch) -> None:
    rng = np.random.default_rng(24)
    source = rng.random((20, 24, 3), dtype=np.float32)
    requests = _plain_requests(rng, 5, 3)
    backend = gl.GLBackend()
    _limited(backend, monkeypatch, max_shared_bytes=512)
    backend.prepare(source, 5)
    with pytest.raises(BackendError, match=r"kth_bound\.comp needs \d+ bytes of shared memory"):
        backend.shortlists(requests, 0.1, 3)
    backend.fields(requests)  # the cost kernel needs none
    backend.close()


def test_every_step_checks_the_gl_error_state(gl: Any, monkeypatch) -> None:
    steps: list[str] = []
    original = gl._check

    def spy(ctx: Any, what: str) -> None:
        steps.append(what)
        original(ctx, what)

    monkeypatch.setattr(gl, "_check", spy)
    rng = np.random.default_rng(25)
    source = rng.random((20, 24, 3), dtype=np.float32)
    requests = _plain_requests(rng, 5, 3)
    backend = gl.GLBackend()
    backend.prepare(source, 5)
    assert steps == ["the texture upload"]
    backend.fields(requests)
    upload, cost = "the upload of the level's inputs", "the cost_field.comp dispatch"
    assert steps[1:] == [upload, cost, "the readback of the cost fields"]
    del steps[:]
    backend.shortlists(requests, 0.1, 3)
    kth, compact = "the kth_bound.comp dispatch", "the shortlist.comp dispatch"
    assert steps == [upload, cost, kth, compact, "the readback of the shortlist"]
    del steps[:]
    monkeypatch.setattr(gl, "MAX_ENTRIES", 0)  # overflow: the dense field is read instead
    backend.shortlists(requests, 0.1, 3)
    assert steps == [upload, cost, kth, compact, "the readback of the cost fields"]
    backend.close()


def test_a_gl_error_names_the_step(gl: Any) -> None:
    class Failed:
        error = "GL_INVALID_OPERATION"

    with pytest.raises(BackendError, match=r"GL_INVALID_OPERATION during the kth_bound\.comp"):
        gl._check(Failed(), "the kth_bound.comp dispatch")
    gl._check(type("Fine", (), {"error": "GL_NO_ERROR"})(), "anything")


# --------------------------------------------------------------------------------------------
# The k-th bound: a radix select on the GPU, exactly numpy's k-th smallest
# --------------------------------------------------------------------------------------------


def _kth_on_gpu(backend: Any, minima: NDArray[np.float32], k: int) -> NDArray[np.float32]:
    """U of kth_bound.comp for each row of ``minima`` (n x count), as the backend runs it."""
    n, count = minima.shape
    data = np.ascontiguousarray(minima, dtype=np.float32).tobytes()

    def call(ctx: Any) -> NDArray[np.float32]:
        backend._buffer(ctx, "minima", data)
        header = backend._kth_bound(ctx, n, count, k)
        return np.frombuffer(header.read(16 + 4 * n), np.float32, offset=16).copy()

    return backend._owner.run(call)


def _kth_minima(rng: np.random.Generator, n: int, count: int) -> NDArray[np.float32]:
    """Rows of run minima of every kind the kernel must order: ties, exact zeros, denormals,
    +inf, values that share their top bytes, values spread over many exponents."""
    rows = []
    for row in range(n):
        kind = row % 6
        if kind == 0:
            values = rng.random(count, dtype=np.float32) * 10
        elif kind == 1:  # few distinct values: ties everywhere, zeros among them
            values = rng.choice(np.array([0.0, 0.5, 0.5001, 3.0], np.float32), count)
        elif kind == 2:  # neighbours in the bit order: only the last pass separates them
            bits = np.uint32(0x3F800000) + rng.integers(0, 300, count).astype(np.uint32)
            values = bits.view(np.float32)
        elif kind == 3:  # some +inf (an overflowing run), maybe fewer than k finite
            values = rng.random(count, dtype=np.float32)
            values[rng.random(count) < 0.7] = np.inf
        elif kind == 4:  # denormals, zeros and huge values
            values = (10.0 ** rng.uniform(-44, 38, count)).astype(np.float32)
            values[rng.random(count) < 0.1] = 0.0
        else:  # every minimum infinite
            values = np.full(count, np.inf, np.float32)
        rows.append(values.astype(np.float32))
    return np.stack(rows)


@pytest.mark.parametrize("count", [1, 7, 256, 1000, 5003])
def test_kth_bound_is_the_exact_kth_smallest(gl: Any, count: int) -> None:
    rng = np.random.default_rng(count)
    minima = _kth_minima(rng, 12, count)
    backend = gl.GLBackend()
    backend.prepare(np.zeros((8, 8, 1), np.float32), 4)  # any job: the kernel needs a context
    ks = sorted({1, 2, 3, count // 2 + 1, count - 1, count, count + 1, count + 50} - {0})
    for k in ks:
        got = _kth_on_gpu(backend, minima, k)
        if k <= count:
            want = np.partition(minima, k - 1, axis=1)[:, k - 1]
        else:
            want = np.full(minima.shape[0], np.inf, np.float32)
        np.testing.assert_array_equal(got.view(np.uint32), want.view(np.uint32), err_msg=f"{k}")
    backend.close()


def test_kth_bound_in_small_work_groups(gl: Any, monkeypatch) -> None:
    rng = np.random.default_rng(26)
    minima = _kth_minima(rng, 6, 777)
    want = np.partition(minima, 40, axis=1)[:, 40]
    for invocations in (1, 8, 64):
        backend = gl.GLBackend()
        _limited(backend, monkeypatch, max_invocations=invocations)
        backend.prepare(np.zeros((8, 8, 1), np.float32), 4)
        got = _kth_on_gpu(backend, minima, 41)
        np.testing.assert_array_equal(got.view(np.uint32), want.view(np.uint32))
        backend.close()


@pytest.fixture
def auto_is_gl(gl_info: Any, monkeypatch) -> None:
    """``auto`` resolves to gl here, as on a machine with a hardware GPU."""
    monkeypatch.delenv(registry.BACKEND_VARIABLE, raising=False)
    status = registry.BackendStatus("gl", True, "hardware GPU (test)", gl_info.renderer, True)
    monkeypatch.setattr(registry, "gl_status", lambda create_context=True: status)


def test_auto_on_a_gpu_is_gl_with_a_safety_net(gl_info: Any, auto_is_gl: None) -> None:
    backend = registry.get_backend("auto")
    assert isinstance(backend, FallbackBackend)
    assert backend.name == "gl" and backend.renderer == gl_info.renderer
    texture = _texture("gravel")
    got = quilting.synthesize(texture, (160, 160), block=24, backend="auto", seed=8)
    want = quilting.synthesize(texture, (160, 160), block=24, backend="fft", seed=8)
    assert got.backend == "gl" and got.fallback is None
    assert got.image.tobytes() == want.image.tobytes()


@pytest.mark.parametrize("where", ["shortlists", "driver"])
def test_auto_finishes_on_fft_when_the_gpu_fails(
    gl: Any, auto_is_gl: None, monkeypatch, where: str
) -> None:
    calls = [0]
    if where == "shortlists":
        original = gl.GLBackend.shortlists

        def failing(self: Any, *args: Any) -> Any:
            calls[0] += 1
            if calls[0] > 4:
                raise BackendError("the GPU went away (test)")
            return original(self, *args)

        monkeypatch.setattr(gl.GLBackend, "shortlists", failing)
    else:
        # Inside the GL thread, as a driver failure would come: a moderngl exception.
        original_dispatch = gl.GLBackend._dispatch_unchecked

        def failing(self: Any, ctx: Any, *args: Any) -> Any:
            calls[0] += 1
            if calls[0] > 4:
                raise gl.moderngl.Error("the GPU went away (test)")
            return original_dispatch(self, ctx, *args)

        monkeypatch.setattr(gl.GLBackend, "_dispatch_unchecked", failing)
    texture = _texture("hubble")
    got = quilting.synthesize(texture, (160, 160), block=24, backend="auto", seed=4)
    assert calls[0] == 5  # four levels ran on gl, then it failed once and was left
    want = quilting.synthesize(texture, (160, 160), block=24, backend="fft", seed=4)
    assert got.backend == "fft" and got.renderer == "cpu"
    assert got.fallback is not None
    assert "gl failed" in got.fallback and "the GPU went away (test)" in got.fallback
    assert got.image.tobytes() == want.image.tobytes()


def test_auto_falls_back_when_the_gpu_is_over_its_limits(
    gl_info: Any, auto_is_gl: None, monkeypatch
) -> None:
    monkeypatch.setitem(gl_info.limits, "max_ssbo_bytes", 16 << 10)
    texture = _texture("wood")  # 96x96x3 float32: 108 KiB
    got = quilting.synthesize(texture, (160, 160), block=32, backend="auto", seed=2)
    want = quilting.synthesize(texture, (160, 160), block=32, backend="fft", seed=2)
    assert got.backend == "fft" and got.fallback is not None
    assert "storage-buffer limit" in got.fallback
    assert got.image.tobytes() == want.image.tobytes()


@pytest.mark.parametrize(
    "device,message",
    [("99", "no OpenGL 4.3 context on EGL device 99"), ("x", "QUILTING_GL_DEVICE")],
)
def test_no_context_at_construction(
    gl: Any, auto_is_gl: None, monkeypatch, device: str, message: str
) -> None:
    monkeypatch.setattr(gl, "_owners", dict(gl._owners))  # forget the failed device afterwards
    monkeypatch.setenv(gl.DEVICE_VARIABLE, device)
    texture = _texture("brick")
    got = quilting.synthesize(texture, (160, 160), block=28, backend="auto", seed=1)
    want = quilting.synthesize(texture, (160, 160), block=28, backend="fft", seed=1)
    assert got.backend == "fft" and got.renderer == "cpu"
    assert got.fallback is not None and message in got.fallback
    assert got.image.tobytes() == want.image.tobytes()
    # Asked for by name, the same failure is an error.
    with pytest.raises(BackendError, match=message):
        quilting.synthesize(texture, (160, 160), block=28, backend="gl", seed=1)


# --------------------------------------------------------------------------------------------
# Threads: one context-owning thread, many callers
# --------------------------------------------------------------------------------------------


def test_backends_in_many_threads(gl: Any) -> None:
    jobs = []
    for k, channels in enumerate((1, 3, 4, 3)):
        rng = np.random.default_rng(100 + k)
        source = rng.random((30 + k, 36 - k, channels), dtype=np.float32)
        jobs.append((source, 6 + k, _plain_requests(rng, 6 + k, channels) * 2))

    def run(job: tuple[Array, int, list[CostRequest]], start: threading.Barrier | None) -> Any:
        source, block, requests = job
        backend = gl.GLBackend()
        if start is not None:
            start.wait(timeout=30)
        out = []
        for _ in range(3):
            backend.prepare(source, block)
            out.append((backend.fields(requests), backend.shortlists(requests, 0.1, 3)))
        backend.close()
        return out

    alone = [run(job, None) for job in jobs]
    start = threading.Barrier(len(jobs))
    with ThreadPoolExecutor(len(jobs)) as pool:
        together = list(pool.map(run, jobs, [start] * len(jobs)))
    for first, second in zip(alone, together, strict=True):
        for (fields_a, lists_a), (fields_b, lists_b) in zip(first, second, strict=True):
            np.testing.assert_array_equal(fields_a.values, fields_b.values)
            np.testing.assert_array_equal(fields_a.error_bound, fields_b.error_bound)
            _same_shortlists(lists_a, lists_b)


def test_one_thread_owns_the_context(gl: Any) -> None:
    a, b = gl.GLBackend(), gl.GLBackend()
    assert a._owner is b._owner
    names = {
        a._owner.run(lambda ctx: threading.current_thread().name),
        b._owner.run(lambda ctx: threading.current_thread().name),
    }
    assert names == {f"quilting-gl-{gl.device_index()}"}
    assert threading.current_thread().name not in names


# --------------------------------------------------------------------------------------------
# What auto stands for
# --------------------------------------------------------------------------------------------


def test_auto_without_a_gpu_device_is_fft_without_a_context(gl: Any, monkeypatch) -> None:
    monkeypatch.delenv(registry.BACKEND_VARIABLE, raising=False)
    monkeypatch.setattr(gl, "gpu_device_nodes", lambda: [])

    def no_probe(index: int | None = None) -> Any:
        raise AssertionError("auto made a GL context on a machine without a GPU")

    monkeypatch.setattr(gl, "probe", no_probe)
    assert registry.resolve_name("auto") == "fft"
    assert "no GPU device" in registry.auto_choice()[1]
    assert isinstance(registry.get_backend("auto"), FFTBackend)


def test_auto_on_a_software_renderer_is_fft(gl: Any, gl_info: Any, monkeypatch) -> None:
    monkeypatch.delenv(registry.BACKEND_VARIABLE, raising=False)
    monkeypatch.setattr(gl, "gpu_device_nodes", lambda: ["/dev/dri/renderD128"])
    if not gl_info.software:  # on a GPU machine, pretend the context is llvmpipe's
        software = dataclasses.replace(gl_info, renderer="llvmpipe (LLVM 15.0.6, 256 bits)")
        monkeypatch.setattr(gl, "probe", lambda index=None: software)
    assert registry.resolve_name("auto") == "fft"
    assert "software rasterizer" in registry.auto_choice()[1]
    assert isinstance(registry.get_backend("auto"), FFTBackend)
    status = registry.gl_status()
    assert status.available and not status.preferred


def test_auto_on_a_hardware_renderer_is_gl(gl: Any, gl_info: Any, monkeypatch) -> None:
    monkeypatch.delenv(registry.BACKEND_VARIABLE, raising=False)
    monkeypatch.setattr(gl, "gpu_device_nodes", lambda: ["/dev/nvidia0"])
    hardware = dataclasses.replace(gl_info, renderer="NVIDIA H100 PCIe/PCIe/SSE2")
    monkeypatch.setattr(gl, "probe", lambda index=None: hardware)
    assert registry.resolve_name("auto") == "gl"
    assert "hardware GPU" in registry.auto_choice()[1]
    backend = registry.get_backend("auto")
    assert isinstance(backend, FallbackBackend) and backend.name == "gl"


def test_software_renderer_names(gl: Any, gl_info: Any) -> None:
    for renderer, software in [
        ("llvmpipe (LLVM 15.0.6, 256 bits)", True),
        ("softpipe", True),
        ("Software Rasterizer", True),
        ("Mesa Intel(R) UHD Graphics 620 (KBL GT2)", False),
        ("NVIDIA H100 80GB HBM3/PCIe/SSE2", False),
    ]:
        assert dataclasses.replace(gl_info, renderer=renderer).software is software, renderer


def test_quilting_backend_variable(gl: Any, monkeypatch) -> None:
    monkeypatch.setattr(gl, "gpu_device_nodes", lambda: [])
    monkeypatch.setenv(registry.BACKEND_VARIABLE, "gl")
    backend = registry.get_backend("auto")
    assert isinstance(backend, gl.GLBackend) and backend.name == "gl"
    assert registry.resolve_name("auto") == "gl"
    monkeypatch.setenv(registry.BACKEND_VARIABLE, "auto")
    assert registry.resolve_name("auto") == "fft"
    monkeypatch.setenv(registry.BACKEND_VARIABLE, "cuda")
    with pytest.raises(InvalidParameterError, match="QUILTING_BACKEND") as caught:
        registry.get_backend("auto")
    assert caught.value.parameter == "QUILTING_BACKEND" and caught.value.value == "cuda"


def test_binding_slots_are_written_once(gl: Any) -> None:
    # The shaders name every buffer's slot by its BINDING_ define, never by a number, and the
    # backend binds through the same table: the two cannot drift apart.
    shaders = importlib.resources.files("quilting.shaders")
    texts = {
        entry.name: entry.read_text("utf-8")
        for entry in shaders.iterdir()
        if entry.name.endswith((".comp", ".glsl"))
    }
    used: set[str] = set()
    for name, text in texts.items():
        assert not re.search(r"binding\s*=\s*\d", text), name
        used |= set(re.findall(r"binding\s*=\s*BINDING_(\w+)", text))
    assert used == {buffer.upper() for buffer in gl.BINDINGS}
    assert len(set(gl.BINDINGS.values())) == len(gl.BINDINGS)  # no two buffers share a slot
    backend = Path(gl.__file__).read_text()
    assert backend.count("bind_to_storage_buffer(") == 1  # in GLBackend._bound only


def test_includes_are_resolved(gl: Any) -> None:
    for name in gl.SHADERS:
        source = gl.shader_source(name, {})
        assert "#include" not in source, name
    assert "struct Request" in gl.shader_source("cost_field.comp", {})
    assert "buffer Header" in gl.shader_source("kth_bound.comp", {})
