"""The cost model: batches that fit their memory, refusals that say what fits, and budgets
that never change an output."""

from __future__ import annotations

import hashlib
import re
import tracemalloc

import numpy as np
import pytest
from textures import texture

import quilting
from quilting.core import budget as model
from quilting.core.fields import CostRequest, ExactScorer
from quilting.core.options import SynthesisOptions, TransferOptions


def test_batch_keeps_the_call_temporaries_under_the_working_memory() -> None:
    for side in (64, 256, 1024, 3000):
        (shape,) = model.synthesis_passes((side, side, 3), (1024, 1024), SynthesisOptions(), "fft")
        for working in (8 << 20, 64 << 20, 384 << 20):
            batch = shape.batch(working, threads=2)
            assert 1 <= batch <= model.MAX_BATCH
            if batch > 1:
                assert shape.in_flight_bytes(batch, 2, fill=1.0) <= working
            if batch < model.MAX_BATCH:
                assert shape.in_flight_bytes(batch + 1, 2, fill=1.0) > working


def test_memory_and_time_grow_with_the_texture_and_the_output() -> None:
    options = SynthesisOptions()
    small = model.estimate_synthesis(options, (128, 128, 3), (512, 512))
    wider = model.estimate_synthesis(options, (512, 512, 3), (512, 512))
    larger = model.estimate_synthesis(options, (128, 128, 3), (2048, 2048))
    assert wider.peak_bytes > small.peak_bytes and wider.seconds > small.seconds
    assert larger.peak_bytes > small.peak_bytes and larger.seconds > small.seconds
    assert small.peak_bytes > model.BASE_BYTES


def test_random_mode_computes_no_fields() -> None:
    matched = model.estimate_synthesis(SynthesisOptions(), (1024, 1024, 3), (512, 512))
    random = model.estimate_synthesis(SynthesisOptions(mode="random"), (1024, 1024, 3), (512, 512))
    assert random.work == 0 and random.peak_bytes < matched.peak_bytes


def test_a_job_over_budget_is_refused_with_advice_that_fits() -> None:
    options = SynthesisOptions()
    budget = model.Budget(memory_bytes=1 << 30)
    with pytest.raises(model.JobTooLargeError) as caught:
        model.estimate_synthesis(options, (5000, 5000, 3), (1024, 1024), budget=budget)
    message = caught.value.message
    assert caught.value.code == "job_too_large"
    assert "1.0 GiB" in message and "memory" in message
    found = re.search(r"a texture of at most (\d+)x(\d+)", message)
    assert found, message
    width, height = int(found[1]), int(found[2])
    assert width < 5000
    # The advice is the largest that fits: it fits, a bit more does not.
    model.estimate_synthesis(options, (height, width, 3), (1024, 1024), budget=budget)
    with pytest.raises(model.JobTooLargeError):
        model.estimate_synthesis(options, (height + 64, width + 64, 3), (1024, 1024), budget=budget)


@pytest.mark.parametrize("tileable", ["both", "x", "y"])
def test_a_tileable_job_over_a_memory_budget_gets_advice_on_an_output_that_is_a_job(
    tileable: str,
) -> None:
    # The advice searched outputs down to 1 pixel, which is no tileable job (a tiled side
    # holds a block): the refusal was that size's InvalidParameterError, not this one.
    options = SynthesisOptions(block=16, tileable=tileable)
    budget = model.Budget(memory_bytes=model.BASE_BYTES + (20 << 20))
    with pytest.raises(model.JobTooLargeError) as caught:
        model.estimate_synthesis(options, (64, 64, 3), (2048, 2048), budget=budget)
    found = re.search(r"an output of at most (\d+)x(\d+)", caught.value.message)
    assert found, caught.value.message
    width, height = int(found[1]), int(found[2])
    model.estimate_synthesis(options, (64, 64, 3), (height, width), budget=budget)
    with pytest.raises(model.JobTooLargeError):
        model.estimate_synthesis(options, (64, 64, 3), (height + 32, width + 32), budget=budget)
    # A budget no tileable output fits says so, still as a job too large.
    with pytest.raises(model.JobTooLargeError, match="raise the budget"):
        model.estimate_synthesis(
            options, (64, 64, 3), (512, 512), budget=model.Budget(memory_bytes=model.BASE_BYTES + 1)
        )


def test_a_matte_over_a_memory_budget_is_a_job_too_large() -> None:
    # Its layers are tileable syntheses: the same advice search, through quilting.matte.
    target = np.full((96, 96, 3), 128, dtype=np.uint8)
    silhouette = np.zeros((96, 96), dtype=np.uint8)
    silhouette[16:80, 16:80] = 255
    with pytest.raises(quilting.JobTooLargeError, match="memory"):
        quilting.matte(
            target,
            [texture("gravel")[:32, :32]],
            silhouette=silhouette,
            block=8,
            backend="fft",
            budget=quilting.Budget(memory_bytes=model.BASE_BYTES + (1 << 20)),
        )


def test_the_job_searches_skip_what_is_no_job() -> None:
    def make(n: int) -> model.Estimate:
        if n < 10:
            raise quilting.InvalidParameterError("size", n, ">= 10")
        return model.Estimate(peak_bytes=n, bound_bytes=n, seconds=0.0, work=0, batch=1)

    assert model.first_job(make, 1, 100) == 10
    assert model.first_job(make, 12, 100) == 12
    assert model.first_job(make, 1, 9) == 10
    assert model.last_job(lambda n: make(110 - n), 1, 200) == 100
    assert model.last_job(lambda n: make(110 - n), 101, 200) == 100


def test_a_time_budget_suggests_a_larger_block() -> None:
    options = SynthesisOptions(block=16)
    needed = model.estimate_synthesis(options, (512, 512, 3), (2048, 2048)).seconds
    budget = model.Budget(seconds=needed / 3)
    with pytest.raises(model.JobTooLargeError) as caught:
        model.estimate_synthesis(options, (512, 512, 3), (2048, 2048), budget=budget)
    found = re.search(r"block >= (\d+)", caught.value.message)
    assert found, caught.value.message
    larger = SynthesisOptions(block=int(found[1]))
    assert model.estimate_synthesis(larger, (512, 512, 3), (2048, 2048)).seconds <= needed / 3


def test_budget_refuses_before_any_work() -> None:
    calls: list[float] = []
    with pytest.raises(quilting.JobTooLargeError):
        quilting.synthesize(
            texture("gravel"),
            (4096, 4096),
            backend="fft",
            budget=quilting.Budget(memory_bytes=model.BASE_BYTES + (20 << 20)),
            progress=lambda fraction, stage: calls.append(fraction),
        )
    assert calls == []


def test_a_budget_that_fits_changes_nothing() -> None:
    sample = texture("gravel")[:96, :96]
    plain = quilting.synthesize(sample, (160, 160), block=24, seed=3, backend="fft")
    roomy = quilting.Budget(memory_bytes=4 << 30, seconds=3600)
    budgeted = quilting.synthesize(
        sample, (160, 160), block=24, seed=3, backend="fft", budget=roomy
    )
    one = quilting.synthesize(sample, (160, 160), block=24, seed=3, backend="fft", max_batch=1)
    digest = hashlib.sha256(plain.image.tobytes()).hexdigest()
    assert hashlib.sha256(budgeted.image.tobytes()).hexdigest() == digest
    assert hashlib.sha256(one.image.tobytes()).hexdigest() == digest


def test_transfer_estimate_counts_every_pass() -> None:
    one = model.estimate_transfer(TransferOptions(iterations=1), (256, 256, 3), (512, 512))
    three = model.estimate_transfer(TransferOptions(iterations=3), (256, 256, 3), (512, 512))
    assert three.seconds > 2 * one.seconds


def test_transfer_and_matte_take_a_budget() -> None:
    sample = texture("gravel")
    with pytest.raises(quilting.JobTooLargeError):
        quilting.transfer(
            sample,
            sample,
            backend="fft",
            budget=quilting.Budget(memory_bytes=model.BASE_BYTES + (1 << 20)),
        )
    target = np.full((64, 64, 3), 128, dtype=np.uint8)
    silhouette = np.zeros((64, 64), dtype=np.uint8)
    silhouette[8:56, 8:56] = 255
    with pytest.raises(quilting.JobTooLargeError):
        quilting.matte(
            target,
            [sample],
            silhouette=silhouette,
            block=16,
            backend="fft",
            budget=quilting.Budget(seconds=1e-6),
        )


def test_exact_scores_do_not_depend_on_the_batch() -> None:
    rng = np.random.default_rng(5)
    source = rng.random((40, 40, 3), dtype=np.float32)
    mask = np.zeros((12, 12), dtype=np.float32)
    mask[:, :3] = 1
    mask[:3, :] = 0.5
    request = CostRequest(
        template=rng.random((12, 12, 3), dtype=np.float32),
        mask=mask,
        previous=rng.random((12, 12, 3), dtype=np.float32),
        previous_weight=0.3,
    )
    ys, xs = np.divmod(np.arange(29 * 29), 29)
    whole = ExactScorer(source, 12).costs(request, ys, xs)
    scorer = ExactScorer(source, 12)
    chunked = np.concatenate(
        [scorer.costs(request, ys[k : k + 1], xs[k : k + 1]) for k in range(ys.size)]
    )
    assert np.array_equal(whole, chunked)
    # And both are the direct sums.
    block = np.lib.stride_tricks.sliding_window_view(source, (12, 12), axis=(0, 1))
    block = block.transpose(0, 1, 3, 4, 2).reshape(29 * 29, 12, 12, 3).astype(np.float64)
    direct = (mask[..., None] * (block - request.template) ** 2).sum(axis=(1, 2, 3))
    direct += 0.3 * ((block - request.previous) ** 2).sum(axis=(1, 2, 3))
    np.testing.assert_allclose(chunked, direct, rtol=1e-10)


def test_budget_rejects_nonsense() -> None:
    with pytest.raises(ValueError):
        model.Budget(memory_bytes=1000)
    with pytest.raises(ValueError):
        model.Budget(seconds=0)


@pytest.mark.parametrize(
    ("shape", "dtype"),
    [((300, 420, 3), np.uint8), ((256, 256), np.uint16), ((200, 180, 4), np.float32)],
)
def test_the_tile_estimate_bounds_make_tileable_memory(shape, dtype) -> None:
    rng = np.random.default_rng(1)
    image = (rng.random(shape) * (255 if dtype == np.uint8 else 1)).astype(dtype)
    if dtype == np.uint16:
        image = (rng.random(shape) * 65535).astype(dtype)
    found = model.estimate_tile(shape, itemsize=image.dtype.itemsize)
    tracemalloc.start()
    try:
        quilting.make_tileable(image)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    # numpy reports its buffers to tracemalloc: the call's own arrays, the interpreter aside.
    predicted = found.bound_bytes - model.BASE_BYTES
    assert peak <= predicted, (peak, predicted)
    assert peak >= 0.5 * predicted, (peak, predicted)  # a bound, not a blanket


@pytest.mark.parametrize(
    ("shape", "dtype"),
    [((300, 420, 3), np.uint8), ((256, 256), np.uint16), ((200, 180, 4), np.float64)],
)
def test_the_tile_estimate_bounds_the_poisson_blend_too(shape, dtype) -> None:
    rng = np.random.default_rng(2)
    image = rng.random(shape)
    image = (image * 255).astype(dtype) if dtype == np.uint8 else image.astype(dtype)
    if dtype == np.uint16:
        image = (rng.random(shape) * 65535).astype(dtype)
    found = model.estimate_tile(shape, itemsize=image.dtype.itemsize, blend="poisson")
    plain = model.estimate_tile(shape, itemsize=image.dtype.itemsize)
    assert found.seconds > plain.seconds and found.bound_bytes >= plain.bound_bytes
    tracemalloc.start()
    try:
        quilting.make_tileable(image, blend="poisson")
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    predicted = found.bound_bytes - model.BASE_BYTES
    assert peak <= predicted, (peak, predicted)
    assert peak >= 0.5 * predicted, (peak, predicted)


def test_a_tile_over_budget_is_refused_before_work_naming_an_image_that_fits() -> None:
    budget = model.Budget(memory_bytes=model.BASE_BYTES + (120 << 20))
    with pytest.raises(model.JobTooLargeError) as caught:
        model.estimate_tile((3000, 4000, 3), budget=budget)
    found = re.search(r"an image of at most (\d+)x(\d+)", caught.value.message)
    assert found, caught.value.message
    width, height = int(found[1]), int(found[2])
    assert width < 4000 and abs(width / height - 4 / 3) < 0.01
    model.estimate_tile((height, width, 3), budget=budget)
    with pytest.raises(model.JobTooLargeError):
        model.estimate_tile((height + 8, width + 8, 3), budget=budget)
    # The public call checks the same before any work: an array it could not even view is
    # never read.
    big = np.broadcast_to(np.zeros(3, dtype=np.uint8), (3000, 4000, 3))
    with pytest.raises(quilting.JobTooLargeError):
        quilting.make_tileable(big, budget=budget)
    seconds = model.estimate_tile((3000, 4000, 3)).seconds
    with pytest.raises(quilting.JobTooLargeError, match="would take about"):
        quilting.make_tileable(big, budget=model.Budget(seconds=seconds / 2))


def test_a_tile_by_filling_is_costed_as_a_fill_and_refused_naming_an_image_that_fits() -> None:
    shape = (900, 1200, 3)
    # The whole image is the bands' bounding box: the fill's own estimate, unchanged.
    tiled = model.estimate_tile(shape, method="fill")
    assert tiled == model.estimate_fill(quilting.FillOptions(), shape, shape[:2])
    budget = model.Budget(memory_bytes=model.BASE_BYTES + (30 << 20))
    with pytest.raises(model.JobTooLargeError) as caught:
        model.estimate_tile(shape, method="fill", budget=budget)
    # The advice is an image, as for the cuts (not "a smaller hole": the caller gave none).
    found = re.search(r"an image of at most (\d+)x(\d+)", caught.value.message)
    assert found, caught.value.message
    width, height = int(found[1]), int(found[2])
    model.estimate_tile((height, width, 3), method="fill", budget=budget)
    with pytest.raises(model.JobTooLargeError):
        model.estimate_tile((height + 8, width + 8, 3), method="fill", budget=budget)
    rng = np.random.default_rng(0)
    image = rng.integers(0, 256, shape, dtype=np.uint8)
    with pytest.raises(model.JobTooLargeError, match=f"{width}x{height}"):
        quilting.make_tileable(image, method="fill", budget=budget)
