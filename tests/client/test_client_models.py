"""The values the client returns (``quilting_client.models``), built directly.

Covers ``JobStatus.from_json`` (every documented member kept with its type, extra members
tolerated and kept in ``raw`` only, members of the wrong type taking their defaults, a
document without a string ``id`` and ``status`` refused with ``ValueError`` and never a
``KeyError``), the status's equality, hash, repr and immutability, values round-tripping
through JSON, ``is_terminal`` and ``TERMINAL_STATES``; and ``SynthesisResult`` and
``WangTilesResult``: bytes that carry the job id, companions, extraction summaries, manifest
and tiles, each a copy of what was given.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import pickle
from typing import Any

import pytest
from client_fakes import NORMAL, RESULT

from quilting_client import models
from quilting_client.models import (
    TERMINAL_STATES,
    JobStatus,
    SynthesisResult,
    WangTilesResult,
)

STATES = ["queued", "running", "done", "failed", "cancelled"]

#: A status with every documented member set to a value other than its default.
FULL: dict[str, Any] = {
    "id": "job-7",
    "status": "done",
    "progress": 1,
    "stage": "blending",
    "backend": "gl",
    "renderer": "NVIDIA H100/PCIe/SSE2",
    "fallback": "GL context lost",
    "timings": {"total": 2, "quilt": 1.25},
    "error": None,
    "width": 640,
    "height": 480,
    "companions": ["normal", "roughness"],
    "result": "/jobs/job-7/result",
    "layout": "/jobs/job-7/layout",
    "created": 1700000000,
    "started": 1700000001.5,
    "finished": 1700000003.25,
    "stats": {"blocks": 12, "seam_error_mean": 0.5},
    "operation": "wang_tiles",
    "manifest": "/jobs/job-7/manifest",
}

#: Each attribute of a JobStatus and the member of FULL it is read from, as parsed.
EXPECTED: dict[str, Any] = {
    **FULL,
    "progress": 1.0,
    "timings": {"total": 2.0, "quilt": 1.25},
    "companions": ("normal", "roughness"),
    "created": 1700000000.0,
}


def test_every_documented_member_is_kept() -> None:
    job = JobStatus.from_json(FULL)
    fields = {f.name for f in dataclasses.fields(JobStatus)} - {"raw"}
    assert fields == set(EXPECTED)
    for name, value in EXPECTED.items():
        got = getattr(job, name)
        assert got == value, name
        assert type(got) is type(value), name
    assert job.raw == FULL


def test_the_defaults_of_a_bare_status() -> None:
    job = JobStatus.from_json({"id": "j", "status": "queued"})
    assert job == JobStatus("j", "queued")
    assert (job.progress, job.stage, job.operation) == (0.0, "", "synthesize")
    assert job.timings == {} and job.companions == ()
    for name in ("backend", "renderer", "fallback", "error", "width", "height", "result"):
        assert getattr(job, name) is None, name
    for name in ("layout", "created", "started", "finished", "stats", "manifest"):
        assert getattr(job, name) is None, name


def test_extra_members_are_tolerated_kept_in_raw_and_not_compared() -> None:
    plain = JobStatus.from_json(FULL)
    extended = JobStatus.from_json({**FULL, "gpu": {"name": "h100"}, "priority": 3})
    assert extended == plain and hash(extended) == hash(plain)
    assert extended.raw["gpu"] == {"name": "h100"} and extended.raw["priority"] == 3
    assert not hasattr(extended, "gpu") and not hasattr(extended, "priority")


@pytest.mark.parametrize(
    "data",
    [
        {},
        {"status": "done"},
        {"id": "j1"},
        {"id": 1, "status": "done"},
        {"id": "j1", "status": 3},
        {"id": None, "status": None},
        {"id": b"j1", "status": "done"},
    ],
)
def test_a_status_without_string_id_and_status_is_a_value_error(data: dict[str, Any]) -> None:
    with pytest.raises(ValueError, match="'id' and 'status'") as caught:
        JobStatus.from_json({"progress": 0.5, "stage": "x", **data})
    assert not isinstance(caught.value, KeyError)


def test_a_partial_full_status_still_needs_both_members() -> None:
    for missing in ("id", "status"):
        data = {k: v for k, v in FULL.items() if k != missing}
        with pytest.raises(ValueError, match=repr(missing)):
            JobStatus.from_json(data)


@pytest.mark.parametrize("data", [None, [], ["id", "status"], "job", 3, b"{}"])
def test_a_status_that_is_not_an_object_is_a_value_error(data: Any) -> None:
    with pytest.raises(ValueError, match=type(data).__name__):
        JobStatus.from_json(data)


@pytest.mark.parametrize(
    ("member", "value", "attribute", "expected"),
    [
        ("progress", "0.5", "progress", 0.0),
        ("progress", True, "progress", 0.0),
        ("progress", None, "progress", 0.0),
        ("stage", 3, "stage", ""),
        ("backend", 1, "backend", None),
        ("width", 64.0, "width", None),
        ("width", True, "width", None),
        ("height", "32", "height", None),
        ("timings", [1, 2], "timings", {}),
        ("timings", {"a": "1", "b": True, "c": None, "d": 3}, "timings", {"d": 3.0}),
        ("error", "it broke", "error", None),
        ("companions", "normal", "companions", ()),
        ("companions", {"normal": 1}, "companions", ()),
        ("created", "yesterday", "created", None),
        ("created", False, "created", None),
        ("stats", [1], "stats", None),
        ("operation", None, "operation", "synthesize"),
        ("operation", 5, "operation", "synthesize"),
        ("manifest", ["m"], "manifest", None),
    ],
)
def test_a_member_of_the_wrong_type_takes_its_default(
    member: str, value: object, attribute: str, expected: object
) -> None:
    job = JobStatus.from_json({"id": "j", "status": "running", member: value})
    assert getattr(job, attribute) == expected
    assert type(getattr(job, attribute)) is type(expected)
    assert job.raw[member] == value


@pytest.mark.parametrize("member", ["created", "started", "finished"])
def test_a_zero_timestamp_is_kept_not_dropped(member: str) -> None:
    job = JobStatus.from_json({"id": "j", "status": "running", member: 0})
    assert getattr(job, member) == 0.0 and getattr(job, member) is not None


def test_mappings_are_copied_from_the_document() -> None:
    data = json.loads(json.dumps({**FULL, "error": {"code": "x", "detail": "d"}}))
    job = JobStatus.from_json(data)
    data["timings"]["total"] = 99
    data["error"]["code"] = "changed"
    data["stats"]["blocks"] = 0
    data["companions"].append("extra")
    data["new"] = True
    assert job.timings["total"] == 2.0 and job.error == {"code": "x", "detail": "d"}
    assert job.stats == FULL["stats"] and job.companions == ("normal", "roughness")
    assert "new" not in job.raw


def test_a_status_round_trips_through_json() -> None:
    job = JobStatus.from_json(FULL)
    assert JobStatus.from_json(json.loads(json.dumps(job.raw))) == job
    # The attributes written back as the service's JSON give the same status.
    written = {
        f.name: getattr(job, f.name) for f in dataclasses.fields(JobStatus) if f.name != "raw"
    }
    written["companions"] = list(job.companions)
    again = JobStatus.from_json(json.loads(json.dumps(written)))
    assert again == job and repr(again) == repr(job)


def test_a_status_is_immutable() -> None:
    job = JobStatus.from_json(FULL)
    for name in ("id", "status", "progress", "companions", "raw"):
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(job, name, None)
    assert job.id == "job-7"


def test_equality_compares_every_member_but_raw() -> None:
    job = JobStatus.from_json(FULL)
    for name in EXPECTED:
        other = FULL[name]
        changed = {**FULL, name: other + "x" if isinstance(other, str) else None}
        if name in ("progress",):
            changed[name] = 0.5
        if name == "error":
            changed[name] = {"code": "x"}
        assert JobStatus.from_json(changed) != job, name


def test_a_status_is_hashable_and_equal_statuses_hash_alike() -> None:
    one = JobStatus.from_json(FULL)
    two = JobStatus.from_json(json.loads(json.dumps(FULL)))
    assert one == two and hash(one) == hash(two)
    assert len({one, two, JobStatus("other", "done")}) == 2


def test_repr_names_the_job_and_leaves_raw_out() -> None:
    job = JobStatus.from_json({**FULL, "secret_extra": "do-not-show"})
    text = repr(job)
    assert text.startswith("JobStatus(") and "id='job-7'" in text and "status='done'" in text
    assert "raw" not in text and "do-not-show" not in text


@pytest.mark.parametrize("state", STATES)
def test_is_terminal_for_done_failed_and_cancelled_only(state: str) -> None:
    job = JobStatus.from_json({"id": "j", "status": state})
    assert job.is_terminal is (state in {"done", "failed", "cancelled"})
    assert JobStatus.from_json({"id": "j", "status": "unknown-future"}).is_terminal is False


def test_terminal_states_are_the_three_documented() -> None:
    assert frozenset({"done", "failed", "cancelled"}) == TERMINAL_STATES
    assert isinstance(TERMINAL_STATES, frozenset)


def test_a_status_survives_a_pickle() -> None:
    job = JobStatus.from_json({**FULL, "gpu": "h100"})
    again = pickle.loads(pickle.dumps(job))
    assert again == job and again.raw == job.raw


def test_the_module_exports_what_it_documents() -> None:
    assert set(models.__all__) == {
        "TERMINAL_STATES",
        "JobStatus",
        "SynthesisResult",
        "WangTilesResult",
    }


# -- results ---------------------------------------------------------------------------------


def test_a_synthesis_result_is_its_png_bytes() -> None:
    result = SynthesisResult(RESULT, job_id="j1")
    assert issubclass(type(result), bytes) and result == RESULT and bytes(result) == RESULT
    assert len(result) == len(RESULT) and result.startswith(b"\x89PNG")
    assert result.job_id == "j1"


def test_a_synthesis_result_s_defaults() -> None:
    result = SynthesisResult(RESULT)
    assert result.job_id is None and result.companions == {} and result.extracted == []
    # Each result has its own containers.
    result.companions["x"] = NORMAL
    assert SynthesisResult(RESULT).companions == {}


def test_a_synthesis_result_keeps_copies_of_what_it_is_given() -> None:
    companions = {"normal": NORMAL}
    summary = {"method": "lkm", "foreground": "ml", "unknown": 0.25}
    extracted = [summary, None]
    result = SynthesisResult(RESULT, job_id="j", companions=companions, extracted=extracted)
    assert result.companions == {"normal": NORMAL} and result.extracted == [summary, None]
    companions["other"] = RESULT
    summary["method"] = "cf"
    extracted.append(None)
    assert result.companions == {"normal": NORMAL}
    assert result.extracted == [{"method": "lkm", "foreground": "ml", "unknown": 0.25}, None]


def test_a_synthesis_result_takes_extracted_from_any_sequence() -> None:
    result = SynthesisResult(RESULT, extracted=({"method": "knn"}, None))
    assert result.extracted == [{"method": "knn"}, None]
    assert isinstance(result.extracted, list)


def test_a_synthesis_result_survives_copy_and_pickle() -> None:
    result = SynthesisResult(RESULT, job_id="j", companions={"n": NORMAL}, extracted=[None])
    for again in (pickle.loads(pickle.dumps(result)), copy.copy(result), copy.deepcopy(result)):
        assert isinstance(again, SynthesisResult) and again == RESULT
        assert (again.job_id, again.companions, again.extracted) == ("j", {"n": NORMAL}, [None])


def test_a_wang_result_survives_copy_and_pickle() -> None:
    tiles = WangTilesResult(RESULT, manifest=MANIFEST, job_id="w1")
    for again in (pickle.loads(pickle.dumps(tiles)), copy.copy(tiles), copy.deepcopy(tiles)):
        assert isinstance(again, WangTilesResult) and again == RESULT
        assert (again.manifest, again.job_id) == (MANIFEST, "w1")


def test_a_synthesis_result_writes_to_a_file_as_is(tmp_path: Any) -> None:
    path = tmp_path / "out.png"
    path.write_bytes(SynthesisResult(RESULT, job_id="j"))
    assert path.read_bytes() == RESULT


MANIFEST: dict[str, Any] = {
    "format": "quilting.wang",
    "tile": 32,
    "colors": 2,
    "rows": 4,
    "columns": 4,
    "tiles": [
        {"index": 0, "x": 0, "y": 0, "n": 0, "e": 1, "s": 0, "w": 1},
        {"index": 1, "x": 32, "y": 0, "n": 1, "e": 0, "s": 1, "w": 0},
    ],
}


def test_a_wang_result_is_its_atlas_with_the_manifest() -> None:
    tiles = WangTilesResult(RESULT, manifest=MANIFEST, job_id="w1")
    assert issubclass(type(tiles), bytes) and tiles == RESULT
    assert tiles.atlas == RESULT and type(tiles.atlas) is bytes
    assert tiles.manifest == MANIFEST and tiles.job_id == "w1"
    assert tiles.tiles == MANIFEST["tiles"]
    assert WangTilesResult(RESULT, manifest={}).job_id is None


def test_a_wang_result_needs_a_manifest() -> None:
    with pytest.raises(TypeError, match="manifest"):
        WangTilesResult(RESULT)  # type: ignore[call-arg]


def test_a_wang_result_s_manifest_and_tiles_are_copies() -> None:
    manifest = json.loads(json.dumps(MANIFEST))
    tiles = WangTilesResult(RESULT, manifest=manifest)
    manifest["colors"] = 9
    assert tiles.manifest["colors"] == 2
    listed = tiles.tiles
    listed[0]["index"] = 99
    listed.append({"index": 5})
    assert tiles.tiles == MANIFEST["tiles"]


@pytest.mark.parametrize(
    ("found", "expected"),
    [
        (None, []),
        ("tiles", []),
        ({"index": 0}, []),
        ([{"index": 0}, 3, None, "x", [1], {"index": 1}], [{"index": 0}, {"index": 1}]),
        ([], []),
    ],
)
def test_wang_tiles_are_the_manifest_s_tile_objects_only(
    found: object, expected: list[dict[str, Any]]
) -> None:
    manifest = {} if found is None else {"tiles": found}
    assert WangTilesResult(RESULT, manifest=manifest).tiles == expected
