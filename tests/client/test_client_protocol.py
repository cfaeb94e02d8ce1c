"""The wire format (``quilting_client._protocol``): the requests built, the status documents
and the event stream parsed, without a transport."""

from __future__ import annotations

import json
from pathlib import Path

import httpx
import pytest
from client_fakes import (
    LAYER_0,
    LAYER_1,
    MATTE_STATS,
    NORMALS_IN,
    ROUGH,
    SILHOUETTE,
    TARGET,
    TEXTURE,
    job_json,
    matte_json,
)

from quilting_client import (
    JobStatus,
)
from quilting_client import _protocol as proto
from quilting_client._events import ServerEvent, SSEDecoder


def test_job_status_ignores_unknown_keys_and_tolerates_missing_ones() -> None:
    job = JobStatus.from_json({"id": "x", "status": "done", "progress": 1, "brand_new": True})
    assert job.progress == 1.0 and job.companions == () and job.error is None
    # A service from before transfer does not say the operation: it only synthesized.
    assert job.operation == "synthesize"
    assert JobStatus.from_json(
        {"id": "x", "status": "done", "operation": "transfer"}
    ).operation == ("transfer")
    assert job.is_terminal and hash(job) == hash(JobStatus.from_json(dict(job.raw)))
    full = JobStatus.from_json(job_json("done", companions=["normal"], timings={"total": 1.5}))
    assert full.companions == ("normal",) and full.timings == {"total": 1.5}
    assert full.result == "/jobs/j1/result" and full.width == 64
    with pytest.raises(ValueError):
        JobStatus.from_json({"status": "done"})


def test_sse_decoder_follows_the_event_stream_format() -> None:
    decoder = SSEDecoder()
    lines = [": comment", "event: progress", 'data: {"progress":', "data:0.5}", "", "", "data: 3"]
    events = [event for line in lines if (event := decoder.feed(line)) is not None]
    assert events == [ServerEvent("progress", {"progress": 0.5})]
    # A last event without its blank line is kept; non-object data is wrapped.
    assert decoder.flush() == ServerEvent("message", {"data": 3})
    assert decoder.flush() is None


def test_tile_request_is_one_multipart_post_without_a_job(tmp_path: Path) -> None:
    spec = proto.tile_request(TEXTURE, axes="x", band=None)
    assert (spec.method, spec.path) == ("POST", "/tile")
    # Answered at once: no ?wait=, nothing held, no Idempotency-Key; band None is left out.
    assert spec.params == {} and spec.hold == 0.0 and spec.timeout is None
    assert dict(spec.headers) == {"Accept": "image/png"}
    assert spec.files == (("image", ("image", TEXTURE, "image/png")),)
    assert json.loads(spec.data["options"]) == {"axes": "x"}
    photo = tmp_path / "photo.jpg"
    photo.write_bytes(ROUGH)
    spec = proto.tile_request(photo, axes="both", band=6, timeout=2.5)
    assert spec.files == (("image", ("photo.jpg", ROUGH, "image/jpeg")),)
    assert json.loads(spec.data["options"]) == {"axes": "both", "band": 6}
    assert spec.timeout == 2.5
    spec = proto.tile_request(TEXTURE, axes="x", band=None, blend="poisson")
    assert json.loads(spec.data["options"]) == {"axes": "x", "blend": "poisson"}


def test_a_request_s_own_timeout_replaces_the_client_s() -> None:
    assert proto.request_timeout(60.0, proto.tile_request(TEXTURE, axes="both", band=None)) == (
        httpx.Timeout(60.0)
    )
    spec = proto.tile_request(TEXTURE, axes="both", band=None, timeout=2.5)
    assert proto.request_timeout(60.0, spec) == httpx.Timeout(2.5)


def test_matte_request_puts_the_parts_in_order(tmp_path: Path) -> None:
    mask = tmp_path / "mask.png"
    mask.write_bytes(SILHOUETTE)
    cloud = tmp_path / "cloud.png"
    cloud.write_bytes(LAYER_1)
    spec = proto.matte_request(
        TARGET,
        mask,
        [LAYER_0, str(cloud), ROUGH],
        normals=NORMALS_IN,
        options={"clusters": 8, "light": (1, 1, 2), "block": 32, "seed": 0, "scale": None},
        wait=2.5,
        idempotency_key="m-1",
    )
    assert (spec.method, spec.path) == ("POST", "/matte")
    assert spec.params == {"wait": "2.5"} and spec.hold == 2.5
    assert dict(spec.headers) == {"Idempotency-Key": "m-1"}
    # Target, silhouette, the layers bottom first, normals; bytes are named after their field.
    assert spec.files == (
        ("target", ("target", TARGET, "image/png")),
        ("silhouette", ("mask.png", SILHOUETTE, "image/png")),
        ("layer", ("layer", LAYER_0, "image/png")),
        ("layer", ("cloud.png", LAYER_1, "image/png")),
        ("layer", ("layer", ROUGH, "image/jpeg")),
        ("normals", ("normals", NORMALS_IN, "image/png")),
    )
    # The light goes as a JSON array; None is left to the service.
    assert json.loads(spec.data["options"]) == {
        "clusters": 8,
        "light": [1, 1, 2],
        "block": 32,
        "seed": 0,
    }
    bare = proto.matte_request(
        TARGET, SILHOUETTE, (LAYER_0,), normals=None, options={}, wait=0, idempotency_key=None
    )
    assert [part[0] for part in bare.files] == ["target", "silhouette", "layer"]
    assert dict(bare.headers) == {} and json.loads(bare.data["options"]) == {}


def test_job_status_parses_a_matte_status() -> None:
    done = matte_json("done", timings={"layers": 0.1, "surface": 0.01, "total": 0.2})
    job = JobStatus.from_json(done)
    assert (job.operation, job.status, job.is_terminal) == ("matte", "done", True)
    assert job.layout is None and job.result == "/jobs/j1/result"
    assert job.companions == ("normals", "clusters")
    assert job.stats == MATTE_STATS and job.timings["surface"] == 0.01
    assert hash(job) == hash(JobStatus.from_json(dict(job.raw)))
    queued = JobStatus.from_json(matte_json("queued"))
    assert queued.stats is None and queued.operation == "matte"
