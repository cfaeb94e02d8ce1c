"""Unit tests of :mod:`quilting.service.jobs.results`: each operation's engine call in a
worker and the fields its finished job stores.

Covers
------
- every operation :func:`~quilting.service.jobs.results.result_fields` supports (synthesize,
  transfer, matte, fill, extend, Wang tiles, extract alpha, and a synthesis from several
  examples with an alpha extracted from one): the result PNG decodes to the documented size,
  dtype and channels and holds the pixels the public :mod:`quilting` API gives for the same
  input and options;
- the same input computed twice gives the same bytes (PNG, companions, layout), and the PNG's
  metadata names the operation, the options and the size, never a job id or a time;
- companions come back in their own dtype and channels, rendered with the kind the job names
  ('hard', 'blend' by default), and the stored layout (:class:`quilting.Layout`,
  :class:`quilting.FillLayout`, a Wang manifest) parses and replays to the same companion;
- progress handed to the engine stays in [0, 1] and rises, the encoding is reported last at 1,
  an exception raised from the progress callback stops the job, and a budget too small raises
  :class:`quilting.JobTooLargeError` before any progress.

Inputs are small PNGs (8-64 px) made here with :func:`quilting.io.encode_png`, decoded by
:func:`quilting.service.uploads.decode` as the worker does; nothing is read from disk.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray

import quilting
from quilting import BASE_BYTES, Budget, FillLayout, JobTooLargeError, Layout
from quilting.io import encode_png, read_image, read_image_metadata
from quilting.service.jobs import JobInput
from quilting.service.jobs.results import result_fields
from quilting.service.uploads import decode

Recorder = list[tuple[str, float, str]]

#: Keys a job's PNG metadata must never hold: the same request must give the same bytes.
VOLATILE_KEYS = {"id", "job_id", "job", "created", "started", "finished", "time", "timestamp"}


# --- inputs ---------------------------------------------------------------------------------


def _noise(shape: tuple[int, ...], seed: int, dtype: Any = np.uint8) -> NDArray[Any]:
    rng = np.random.default_rng(seed)
    top = int(np.iinfo(dtype).max)
    found: NDArray[Any] = rng.integers(0, top + 1, shape).astype(dtype)
    return found


def _rgb() -> NDArray[np.uint8]:
    """A 32x32 RGB texture: smooth bands plus noise (seams have something to cut through)."""
    yy, xx = np.mgrid[0:32, 0:32]
    bands = np.stack([40 + 5 * xx, 200 - 4 * yy, 90 + 3 * ((xx + yy) % 16)], axis=-1)
    texture: NDArray[np.uint8] = np.clip(bands + _noise((32, 32, 3), 1) // 6, 0, 255).astype(
        np.uint8
    )
    return texture


def _mask_map() -> NDArray[np.uint8]:
    """A 32x32 gray companion of only 0 and 255."""
    return np.where(_noise((32, 32), 2) > 127, 255, 0).astype(np.uint8)


def _height_map() -> NDArray[np.uint16]:
    """A 32x32 16-bit gray companion."""
    return _noise((32, 32), 3, np.uint16)


def _matte_scene() -> tuple[NDArray[np.uint8], NDArray[np.uint8], NDArray[np.uint8]]:
    """A 48x48 gray target shaded like a bump, its 32x24 box silhouette, a 32x32 RGB layer."""
    yy, xx = np.mgrid[0:48, 0:48]
    target = (80 + 100 * np.exp(-((yy - 24) ** 2 + (xx - 24) ** 2) / 300)).astype(np.uint8)
    silhouette = np.zeros((48, 48), np.uint8)
    silhouette[12:36, 8:40] = 255
    return target, silhouette, _rgb()


def _photo() -> tuple[NDArray[np.uint8], NDArray[np.uint8]]:
    """A 40x40 RGB photo (a red square on blue) and its trimap."""
    inside = np.zeros((40, 40), bool)
    inside[10:30, 10:30] = True
    photo = np.where(inside[..., None], [200, 50, 50], [20, 80, 200]).astype(np.uint8)
    trimap = np.full((40, 40), 128, np.uint8)
    trimap[13:27, 13:27] = 255
    trimap[:7], trimap[33:], trimap[:, :7], trimap[:, 33:] = 0, 0, 0, 0
    return photo, trimap


def _hole() -> NDArray[np.uint8]:
    mask = np.zeros((32, 32), np.uint8)
    mask[10:20, 12:22] = 255
    return mask


EXTEND = {"left": 8, "right": 4, "top": 0, "bottom": 6}


def _spec(operation: str, **changes: Any) -> JobInput:
    """A small job of ``operation``, its uploads encoded as a client sends them."""
    texture = encode_png(_rgb())
    if operation == "synthesize":
        spec = JobInput(texture, {}, {"block": 12, "seed": 3}, 40, 36)
    elif operation == "transfer":
        target = _noise((24, 28), 4)
        spec = JobInput(
            texture,
            {},
            {"block": 8, "seed": 3},
            28,
            24,
            operation="transfer",
            target=encode_png(target),
        )
    elif operation == "matte":
        target, silhouette, layer = _matte_scene()
        spec = JobInput(
            encode_png(layer),
            {},
            {"block": 8, "seed": 3},
            48,
            48,
            operation="matte",
            target=encode_png(target),
            silhouette=encode_png(silhouette),
            layers=[encode_png(layer)],
        )
    elif operation == "fill":
        spec = JobInput(
            texture, {}, {"block": 8, "seed": 3}, 32, 32, operation="fill", mask=encode_png(_hole())
        )
    elif operation == "extend":
        spec = JobInput(texture, {}, {"block": 8, "seed": 3, **EXTEND}, 44, 38, operation="extend")
    elif operation == "wang_tiles":
        options = {"colors": 2, "tile": 16, "block": 8, "seed": 3}
        spec = JobInput(texture, {}, options, 64, 64, operation="wang_tiles")
    else:
        assert operation == "extract_alpha"
        photo, trimap = _photo()
        spec = JobInput(
            encode_png(photo),
            {},
            {"method": "knn"},
            40,
            40,
            operation="extract_alpha",
            trimaps=[encode_png(trimap)],
        )
    for name, value in changes.items():
        setattr(spec, name, value)
    return spec


def _expected(operation: str) -> NDArray[Any]:
    """The public API's image for :func:`_spec`'s job of ``operation``."""
    texture = _rgb()
    if operation == "synthesize":
        return quilting.synthesize(texture, (36, 40), block=12, seed=3).image
    if operation == "transfer":
        return quilting.transfer(texture, _noise((24, 28), 4), block=8, seed=3).image
    if operation == "matte":
        target, silhouette, layer = _matte_scene()
        return quilting.matte(target, [layer], silhouette=silhouette, block=8, seed=3).image
    if operation == "fill":
        return quilting.fill(texture, _hole(), block=8, seed=3).image
    if operation == "extend":
        return quilting.extend(
            texture, quilting.ExtendOptions(block=8, seed=3, left=8, right=4, top=0, bottom=6)
        ).image
    if operation == "wang_tiles":
        return quilting.wang_tiles(texture, colors=2, tile=16, block=8, seed=3).atlas()
    photo, trimap = _photo()
    return quilting.extract_alpha(photo, trimap, method="knn").image


#: (width, height, channels) of each operation's result for :func:`_spec`'s job.
SHAPES = {
    "synthesize": (40, 36, 3),
    "transfer": (28, 24, 3),
    "matte": (48, 48, 3),
    "fill": (32, 32, 3),
    "extend": (44, 38, 3),
    "wang_tiles": (64, 64, 3),
    "extract_alpha": (40, 40, 4),
}
OPERATIONS = sorted(SHAPES)


def _run(
    spec: JobInput,
    calls: Recorder | None = None,
    budget: Budget | None = None,
    progress: Callable[[float, str], None] | None = None,
) -> dict[str, Any]:
    """:func:`result_fields` as the worker calls it: uploads decoded, options from the JSON.
    Every progress and report call goes to ``calls`` in order."""
    calls = [] if calls is None else calls

    def engine_progress(fraction: float, stage: str) -> None:
        calls.append(("progress", fraction, stage))
        if progress is not None:
            progress(fraction, stage)

    def report(fraction: float, stage: str) -> None:
        calls.append(("report", fraction, stage))

    return result_fields(spec, spec.engine_options(), decode(spec), engine_progress, report, budget)


# --- every operation --------------------------------------------------------------------------


@pytest.mark.parametrize("operation", OPERATIONS)
def test_the_result_is_the_public_apis_image_at_the_documented_size(operation: str) -> None:
    fields = _run(_spec(operation))
    image = read_image(fields["png"])
    width, height, channels = SHAPES[operation]
    assert image.shape == (height, width, channels)
    assert image.dtype == np.uint8
    np.testing.assert_array_equal(image, _expected(operation))
    assert isinstance(fields["timings"], dict) and fields["timings"]
    assert isinstance(fields["stats"], dict)


@pytest.mark.parametrize("operation", OPERATIONS)
def test_the_same_job_gives_the_same_bytes_and_its_metadata_names_the_options(
    operation: str,
) -> None:
    spec = _spec(operation)
    first, second = _run(spec), _run(spec)
    assert first["png"] == second["png"]
    assert first["companions"] == second["companions"]
    assert first["layout"] == second["layout"]
    meta = read_image_metadata(first["png"])
    assert meta["operation"] == operation
    assert (meta["width"], meta["height"]) == (spec.width, spec.height)
    for name, value in spec.options.items():
        assert meta[name] == value, name
    assert not VOLATILE_KEYS & set(meta), meta


def test_another_seed_gives_another_image() -> None:
    one = _run(_spec("synthesize"))
    other = _run(_spec("synthesize", options={"block": 12, "seed": 4}))
    assert read_image_metadata(other["png"])["seed"] == 4
    assert not np.array_equal(read_image(one["png"]), read_image(other["png"]))


# --- companions and layouts -----------------------------------------------------------------


def test_synthesis_companions_keep_their_kind_dtype_and_replay_from_the_layout() -> None:
    mask, height = _mask_map(), _height_map()
    spec = _spec(
        "synthesize",
        companions={"mask": encode_png(mask), "height": encode_png(height)},
        companion_kinds={"mask": "hard"},
    )
    fields = _run(spec)
    assert set(fields["companions"]) == {"mask", "height"}
    got_mask = read_image(fields["companions"]["mask"])
    got_height = read_image(fields["companions"]["height"])
    assert got_mask.shape == (36, 40) and got_mask.dtype == np.uint8
    assert got_height.shape == (36, 40) and got_height.dtype == np.uint16
    # 'hard' never mixes values across a seam: only the mask's own values come back.
    assert set(np.unique(got_mask).tolist()) <= {0, 255}

    layout = Layout.from_json(fields["layout"])
    assert tuple(layout.source_shape) == (32, 32)
    np.testing.assert_array_equal(got_mask, quilting.apply_layout(layout, mask, kind="hard"))
    # A companion the job does not name is blended, the default.
    np.testing.assert_array_equal(got_height, quilting.apply_layout(layout, height))
    # The stored layout is the engine's for the same input and options.
    engine = quilting.synthesize(_rgb(), (36, 40), block=12, seed=3)
    assert layout.to_json() == engine.layout.to_json()


def test_a_blended_companion_differs_from_a_hard_one_where_seams_are_blended() -> None:
    mask = encode_png(_mask_map())
    blended = _run(_spec("synthesize", companions={"mask": mask}))
    hard = _run(_spec("synthesize", companions={"mask": mask}, companion_kinds={"mask": "hard"}))
    soft = read_image(blended["companions"]["mask"])
    # The default blend is 'poisson': a blended mask takes values between 0 and 255.
    assert not set(np.unique(soft).tolist()) <= {0, 255}
    assert not np.array_equal(soft, read_image(hard["companions"]["mask"]))


def test_transfer_companions_and_figures() -> None:
    mask = _mask_map()
    spec = _spec(
        "transfer", companions={"mask": encode_png(mask)}, companion_kinds={"mask": "hard"}
    )
    fields = _run(spec)
    got = read_image(fields["companions"]["mask"])
    assert got.shape == (24, 28)
    layout = Layout.from_json(fields["layout"])
    np.testing.assert_array_equal(got, quilting.apply_layout(layout, mask, kind="hard"))
    engine = quilting.transfer(_rgb(), _noise((24, 28), 4), block=8, seed=3)
    assert fields["stats"]["correspondence_error"] == pytest.approx(
        engine.stats.correspondence_error
    )
    assert fields["stats"]["seam_error_total"] == pytest.approx(engine.stats.seam_error_total)


def test_several_examples_quilt_each_examples_companion_and_report_each_extraction() -> None:
    """Two examples, the first a photo with a trimap: its alpha is extracted first; the
    second already has alpha. Their companions come back quilted from both maps."""
    photo, trimap = _photo()
    already = quilting.extract_alpha(photo, trimap, method="knn").image
    maps = [_noise((40, 40), 5), _noise((40, 40), 6)]
    spec = JobInput(
        encode_png(photo),
        {"rough": encode_png(maps[0])},
        {"block": 12, "seed": 2, "matting": "knn"},
        48,
        40,
        examples=[encode_png(photo), encode_png(already)],
        example_companions={"rough": [encode_png(m) for m in maps]},
        trimaps=[encode_png(trimap), None],
        scribbles=[None, None],
    )
    fields = _run(spec)
    expected = quilting.synthesize(
        [photo, already], (40, 48), trimap=[trimap, None], matting="knn", block=12, seed=2
    )
    image = read_image(fields["png"])
    assert image.shape == (40, 48, 4)
    np.testing.assert_array_equal(image, expected.image)
    extracted = fields["stats"]["extracted"]
    assert len(extracted) == 2 and extracted[1] is None
    assert extracted[0]["method"] == "knn"
    layout = Layout.from_json(fields["layout"])
    np.testing.assert_array_equal(
        read_image(fields["companions"]["rough"]), quilting.apply_layout(layout, maps)
    )


def test_fill_keeps_known_pixels_and_its_layout_fills_a_companion_the_same_way() -> None:
    height = _height_map()
    spec = _spec("fill", companions={"height": encode_png(height)})
    fields = _run(spec)
    image, hole = read_image(fields["png"]), _hole() > 0
    np.testing.assert_array_equal(image[~hole], _rgb()[~hole])
    assert fields["stats"]["filled_pixels"] == int(hole.sum())
    assert fields["layout"] is not None and quilting.is_fill_layout(fields["layout"])
    layout = FillLayout.from_json(fields["layout"])
    companion = read_image(fields["companions"]["height"])
    assert companion.dtype == np.uint16 and companion.shape == (32, 32)
    np.testing.assert_array_equal(companion, layout.apply(height))
    np.testing.assert_array_equal(companion[~hole], height[~hole])
    assert read_image_metadata(fields["png"])["version"] == quilting.__version__


def test_extend_places_the_image_and_its_layout_extends_a_companion() -> None:
    mask = _mask_map()
    fields = _run(_spec("extend", companions={"mask": encode_png(mask)}))
    image = read_image(fields["png"])
    top, left = EXTEND["top"], EXTEND["left"]
    np.testing.assert_array_equal(image[top : top + 32, left : left + 32], _rgb())
    assert fields["stats"]["filled_pixels"] == 44 * 38 - 32 * 32
    layout = FillLayout.from_json(fields["layout"])
    companion = read_image(fields["companions"]["mask"])
    assert companion.shape == (38, 44)
    np.testing.assert_array_equal(companion, layout.apply(mask))
    np.testing.assert_array_equal(companion[top : top + 32, left : left + 32], mask)


def test_the_wang_manifest_places_every_tile_of_the_atlas() -> None:
    fields = _run(_spec("wang_tiles"))
    atlas = read_image(fields["png"])
    manifest = json.loads(fields["layout"])
    tiles = quilting.wang_tiles(_rgb(), colors=2, tile=16, block=8, seed=3).tiles
    assert fields["companions"] == {}
    assert manifest["tile"] == 16 and manifest["colors"] == 2
    assert len(manifest["tiles"]) == fields["stats"]["tiles"] == 2**4
    assert fields["stats"]["atlas"] == [64, 64]
    for entry in manifest["tiles"]:
        x, y = entry["x"], entry["y"]
        np.testing.assert_array_equal(atlas[y : y + 16, x : x + 16], tiles[entry["index"]])
    # Every combination of the edges' colours, once.
    combos = {tuple(entry[side] for side in manifest["edges"]) for entry in manifest["tiles"]}
    assert len(combos) == 16


def test_matte_companions_are_the_normals_and_patches_used() -> None:
    fields = _run(_spec("matte"))
    target, silhouette, layer = _matte_scene()
    engine = quilting.matte(target, [layer], silhouette=silhouette, block=8, seed=3)
    assert set(fields["companions"]) == {"normals", "clusters"}
    np.testing.assert_array_equal(read_image(fields["companions"]["normals"]), engine.normal_map())
    np.testing.assert_array_equal(read_image(fields["companions"]["clusters"]), engine.patch_map())
    assert fields["layout"] is None
    meta = read_image_metadata(fields["png"])
    assert meta["light_used"] == pytest.approx(list(engine.light))
    assert fields["stats"]["light"] == pytest.approx(list(engine.light))
    assert fields["stats"]["patches"] == int(engine.patches.max()) + 1


def test_an_extraction_reports_its_summary() -> None:
    fields = _run(_spec("extract_alpha"))
    image = read_image(fields["png"])
    (summary,) = fields["stats"]["extracted"]
    assert summary["method"] == "knn" and summary["foreground"] == "ml"
    # Sure foreground opaque, sure background transparent.
    _, trimap = _photo()
    assert (image[trimap == 255, 3] == 255).all()
    assert (image[trimap == 0, 3] == 0).all()
    assert fields["layout"] is None and fields["companions"] == {}


# --- progress, stopping, budgets ------------------------------------------------------------


@pytest.mark.parametrize("operation", OPERATIONS)
def test_progress_rises_within_0_and_1_and_the_encoding_is_reported_last(operation: str) -> None:
    calls: Recorder = []
    _run(_spec(operation), calls)
    fractions = [fraction for kind, fraction, _ in calls if kind == "progress"]
    assert fractions, "the engine reported no progress"
    assert all(0.0 <= f <= 1.0 for f in fractions), fractions
    assert fractions == sorted(fractions), fractions
    assert calls[-1] == ("report", 1.0, "encoding")
    assert [kind for kind, _, _ in calls].count("report") == 1


class StoppedError(Exception):
    """Raised from a progress callback."""


@pytest.mark.parametrize("operation", OPERATIONS)
def test_raising_from_progress_stops_the_job(operation: str) -> None:
    calls: Recorder = []

    def stop(fraction: float, stage: str) -> None:
        raise StoppedError(stage)

    with pytest.raises(StoppedError):
        _run(_spec(operation), calls, progress=stop)
    # Stopped at the first report: nothing more was computed, nothing encoded.
    assert [kind for kind, _, _ in calls] == ["progress"]


@pytest.mark.parametrize("operation", OPERATIONS)
def test_a_budget_too_small_is_refused_before_any_work(operation: str) -> None:
    calls: Recorder = []
    with pytest.raises(JobTooLargeError) as raised:
        _run(_spec(operation), calls, budget=Budget(memory_bytes=BASE_BYTES + 1024))
    assert raised.value.code == "job_too_large"
    assert calls == []


@pytest.mark.parametrize("operation", OPERATIONS)
def test_a_roomy_budget_changes_nothing(operation: str) -> None:
    roomy = Budget(memory_bytes=BASE_BYTES + 512 * 2**20)
    assert _run(_spec(operation), budget=roomy)["png"] == _run(_spec(operation))["png"]
