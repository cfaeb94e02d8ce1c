"""A job's input crosses processes as bytes (the distributed queue): the round trip is exact,
and the bytes are arrays and JSON only, never a pickle."""

from __future__ import annotations

import io
import zipfile

import numpy as np
import pytest

from quilting.service.jobs import JobInput


def _rng_image(shape: tuple[int, ...], dtype: type[np.generic], seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    high = 65535 if dtype is np.uint16 else 255
    if dtype is np.float32:
        return rng.random(shape, dtype=np.float32)
    return rng.integers(0, high + 1, size=shape).astype(dtype)


def _assert_same(a: JobInput, b: JobInput) -> None:
    for name in ("options", "width", "height", "operation"):
        assert getattr(a, name) == getattr(b, name), name
    for name in ("texture", "target", "source_mask", "silhouette", "normals"):
        x, y = getattr(a, name), getattr(b, name)
        if x is None:
            assert y is None, name
        else:
            assert y.dtype == x.dtype and y.shape == x.shape, name
            np.testing.assert_array_equal(y, x)
    assert list(b.companions) == list(a.companions)  # order kept: it names the outputs
    for name, image in a.companions.items():
        np.testing.assert_array_equal(b.companions[name], image)
    assert len(b.layers) == len(a.layers)
    for x, y in zip(a.layers, b.layers, strict=True):
        assert y.dtype == x.dtype
        np.testing.assert_array_equal(y, x)
    assert b.outputs == a.outputs


def test_synthesis_input_round_trip_keeps_dtypes_companions_and_options() -> None:
    spec = JobInput(
        texture=_rng_image((40, 30, 3), np.uint8, 1),
        companions={
            "zeta": _rng_image((40, 30), np.uint16, 2),
            "alpha": _rng_image((40, 30, 4), np.uint8, 3),
        },
        options={"block": 24, "seed": 7, "tileable": "both", "backend": "fft", "exclude": None},
        width=100,
        height=80,
        source_mask=_rng_image((40, 30), np.uint8, 4),
    )
    _assert_same(spec, JobInput.from_bytes(spec.to_bytes()))


def test_transfer_and_matte_inputs_round_trip() -> None:
    transfer = JobInput(
        texture=_rng_image((32, 32), np.uint8, 5),
        companions={},
        options={"alpha": 0.3, "iterations": 2, "correspondence": "luminance"},
        width=50,
        height=60,
        target=_rng_image((60, 50, 3), np.uint16, 6),
        operation="transfer",
    )
    _assert_same(transfer, JobInput.from_bytes(transfer.to_bytes()))
    layers = [_rng_image((24, 24, 3), np.uint8, 7), _rng_image((20, 20, 4), np.uint8, 8)]
    matte = JobInput(
        texture=layers[0],
        companions={},
        options={"light": [1.0, -0.5, 2.0], "clusters": 4, "scale": 1.5},
        width=64,
        height=48,
        target=_rng_image((48, 64, 3), np.uint8, 9),
        operation="matte",
        layers=layers,
        silhouette=_rng_image((48, 64), np.uint8, 10),
        normals=_rng_image((48, 64, 3), np.float32, 11),
    )
    back = JobInput.from_bytes(matte.to_bytes())
    _assert_same(matte, back)
    assert back.outputs == ["normals", "clusters"]


def test_the_bytes_hold_no_pickle_and_a_pickle_is_refused() -> None:
    spec = JobInput(
        texture=_rng_image((8, 8), np.uint8, 12), companions={}, options={}, width=8, height=8
    )
    with zipfile.ZipFile(io.BytesIO(spec.to_bytes())) as archive:
        for name in archive.namelist():
            header = archive.read(name)[:128]
            assert b"'descr': '|O'" not in header, name  # no object arrays
    # An archive with an object array (a pickle inside) is refused when read back.
    buffer = io.BytesIO()
    meta = b'{"options": {}, "width": 8, "height": 8, "operation": "synthesize", '
    meta += b'"companions": [], "layers": 0}'
    np.savez(buffer, texture=np.array([object()], dtype=object), meta=np.frombuffer(meta, np.uint8))
    with pytest.raises(ValueError, match="allow_pickle"):
        JobInput.from_bytes(buffer.getvalue())
