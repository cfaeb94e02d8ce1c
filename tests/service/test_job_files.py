"""The files a submission hands to its job's input (:mod:`quilting.service.jobs.job_files`)."""

from __future__ import annotations

import dataclasses
import pickle

from quilting.options import QuiltOptions
from quilting.service.forms import Submission
from quilting.service.jobs import JobInput
from quilting.service.jobs.job_files import JobFiles


def _every_file_set() -> dict[str, object]:
    """A value for every JobFiles field, none of them its default."""
    return {
        "target": b"target",
        "source_mask": b"mask0",
        "layers": [b"l0", b"l1"],
        "silhouette": b"sil",
        "normals": b"nrm",
        "companion_kinds": {"m": "hard"},
        "mask": b"hole",
        "source": b"src",
        "examples": [b"t", b"e1"],
        "source_masks": [b"mask0", b"mask1"],
        "example_companions": {"m": [b"m0", b"m1"]},
        "trimaps": [b"tri", None],
        "scribbles": [None, b"scr"],
    }


def test_a_submission_hands_every_file_to_the_job_input_as_copies() -> None:
    """Every JobFiles field reaches the job's input unchanged, and the input holds lists and
    dicts of its own: a submission changed afterwards does not change the queued job."""
    files = _every_file_set()
    assert set(files) == {member.name for member in dataclasses.fields(JobFiles)}
    submission = Submission("synthesize", QuiltOptions(), b"t", {"m": b"m0"}, **files)
    spec = JobInput(b"t", {"m": b"m0"}, {}, 4, 4, **submission.job_files())
    for name, value in files.items():
        assert getattr(spec, name) == value, name
    submission.layers.append(b"late")
    submission.example_companions["m"].append(b"late")
    submission.companion_kinds["n"] = "blend"
    assert spec.layers == [b"l0", b"l1"]
    assert spec.example_companions == {"m": [b"m0", b"m1"]}
    assert spec.companion_kinds == {"m": "hard"}


def test_a_pickle_from_an_older_build_takes_each_missing_file_s_default() -> None:
    """A job pickled before any of the later files existed unpickles with each at its
    default (a fresh list or dict, not one shared between inputs)."""
    state = dict(JobInput(b"t", {}, {"block": 8}, 4, 4, **_every_file_set()).__dict__)
    for member in dataclasses.fields(JobFiles):
        del state[member.name]
    first, second = JobInput.__new__(JobInput), JobInput.__new__(JobInput)
    first.__setstate__(dict(state))
    second.__setstate__(dict(state))
    fresh = JobInput(b"t", {}, {"block": 8}, 4, 4)
    for member in dataclasses.fields(JobFiles):
        assert getattr(first, member.name) == getattr(fresh, member.name), member.name
    assert first.layers is not second.layers
    first.layers.append(b"x")
    assert second.layers == []
    assert pickle.loads(pickle.dumps(first)) == first
