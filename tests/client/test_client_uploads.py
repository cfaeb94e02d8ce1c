"""The files a submission uploads (``quilting_client._uploads``), called directly.

Covers every kind of image source the module takes (a ``str`` path, an ``os.PathLike``, bytes,
a ``bytearray`` or ``memoryview``) giving the same part bytes with the documented file name
and content type; paths that cannot be read raising an ``OSError`` that names them; sources of
other types (a file object, an int, None) refused before any request is made; companions'
names and kinds checked as the service would; and the helpers that turn one image or a
sequence of them into a list.
"""

from __future__ import annotations

import io
import os
import string
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from client_fakes import NORMAL, ROUGH, TEXTURE, FakeService

from quilting_client import ValidationError
from quilting_client import _protocol as proto
from quilting_client import _uploads as uploads

# Neither PNG nor JPEG: a PNG signature cut short, or nothing.
OTHER = b"GIF89a\x01\x00\x01\x00"


class Fspath:
    """A path-like object that is neither ``str`` nor ``pathlib.Path``."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def __fspath__(self) -> str:
        return str(self.path)


def _sources(tmp_path: Path, content: bytes) -> dict[str, Any]:
    """The same image in every kind of source the module takes, with its file name if any."""
    path = tmp_path / "gravel.png"
    path.write_bytes(content)
    return {
        "str": str(path),
        "path": path,
        "pathlike": Fspath(path),
        "bytes": content,
        "bytearray": bytearray(content),
        "memoryview": memoryview(content),
    }


NAMED = {"str", "path", "pathlike"}
KINDS = ["str", "path", "pathlike", "bytes", "bytearray", "memoryview"]


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize(
    ("content", "media"),
    [(TEXTURE, "image/png"), (ROUGH, "image/jpeg"), (OTHER, "application/octet-stream")],
)
def test_every_source_kind_gives_the_same_part(
    tmp_path: Path, kind: str, content: bytes, media: str
) -> None:
    source = _sources(tmp_path, content)[kind]
    field, (filename, data, content_type) = uploads.part("texture", source)
    assert field == "texture"
    assert data == content and type(data) is bytes  # httpx needs plain bytes
    assert content_type == media
    # A file keeps its name; bytes are named after their field.
    assert filename == ("gravel.png" if kind in NAMED else "texture")


@pytest.mark.parametrize("kind", KINDS)
def test_read_source_gives_the_bytes_and_the_name_of_a_file_only(tmp_path: Path, kind: str) -> None:
    data, name = uploads.read_source(_sources(tmp_path, NORMAL)[kind])
    assert data == NORMAL and type(data) is bytes
    assert name == ("gravel.png" if kind in NAMED else None)


def test_a_source_of_bytes_is_copied_not_shared() -> None:
    buffer = bytearray(TEXTURE)
    _, (_, data, _) = uploads.part("texture", buffer)  # type: ignore[arg-type]
    buffer[:4] = b"XXXX"
    assert data == TEXTURE


def test_a_file_s_name_is_its_last_component_only(tmp_path: Path) -> None:
    nested = tmp_path / "a" / "b"
    nested.mkdir(parents=True)
    (nested / "photo.jpeg").write_bytes(ROUGH)
    _, (filename, data, media) = uploads.part("target", nested / "photo.jpeg")
    assert (filename, data, media) == ("photo.jpeg", ROUGH, "image/jpeg")
    assert os.sep not in filename


@pytest.mark.parametrize(
    ("content", "media"),
    [
        (uploads.PNG_SIGNATURE, "image/png"),
        (uploads.PNG_SIGNATURE + b"rest", "image/png"),
        (uploads.PNG_SIGNATURE[:-1], "application/octet-stream"),
        (b"\xff\xd8\xff", "image/jpeg"),
        (b"\xff\xd8", "application/octet-stream"),
        (b"", "application/octet-stream"),
        (b"x" + uploads.PNG_SIGNATURE, "application/octet-stream"),
    ],
)
def test_media_type_is_sniffed_from_the_leading_bytes(content: bytes, media: str) -> None:
    assert uploads.media_type(content) == media


def test_a_missing_file_raises_an_os_error_naming_the_path(tmp_path: Path) -> None:
    missing = tmp_path / "nowhere" / "missing.png"
    for source in (str(missing), missing, Fspath(missing)):
        with pytest.raises(FileNotFoundError) as caught:
            uploads.part("texture", source)
        assert caught.value.filename == str(missing)
        assert str(missing) in str(caught.value)


def test_a_directory_is_not_an_image(tmp_path: Path) -> None:
    with pytest.raises(OSError) as caught:
        uploads.read_source(tmp_path)
    assert caught.value.filename == str(tmp_path)


@pytest.fixture
def binary_file(tmp_path: Path) -> Iterator[Any]:
    path = tmp_path / "open.png"
    path.write_bytes(TEXTURE)
    with path.open("rb") as handle:
        yield handle


def _not_sources(binary: Any) -> list[object]:
    return [binary, io.BytesIO(TEXTURE), io.StringIO("texture"), 42, 1.5, None, ["a.png"]]


def test_sources_of_other_types_are_refused_with_type_error(binary_file: Any) -> None:
    for source in _not_sources(binary_file):
        with pytest.raises(TypeError):
            uploads.read_source(source)  # type: ignore[arg-type]
        with pytest.raises(TypeError):
            uploads.part("texture", source)  # type: ignore[arg-type]
    # Nothing was read from the open file.
    assert binary_file.tell() == 0


def test_a_refused_source_fails_before_any_request(
    connect: Callable[..., Any], binary_file: Any
) -> None:
    service = FakeService()
    client = connect(service)
    # Parameters that take one image: file objects are refused too.
    for source in (binary_file, io.StringIO("texture"), 42):
        with pytest.raises(TypeError):
            client.submit_transfer(TEXTURE, source)
        with pytest.raises(TypeError):
            client.tile(source)
    with pytest.raises(TypeError):
        client.tile(None)
    # Parameters that take one image or a sequence of them; an open file iterates over its
    # lines, which went up as a part each.
    for source in (42, 1.5, None, binary_file, io.BytesIO(TEXTURE), io.StringIO("t.png")):
        with pytest.raises(TypeError):
            client.submit(source, width=8, height=8)
        with pytest.raises(TypeError):
            client.submit_transfer(source, TEXTURE)
        with pytest.raises(TypeError):
            client.submit(TEXTURE, width=8, height=8, companions={"normal": source})
    # A transfer without a target is no synthesis.
    with pytest.raises(TypeError, match="target"):
        client.submit_transfer(TEXTURE, None)
    assert service.requests == []
    assert binary_file.tell() == 0


def test_an_open_file_is_refused_naming_what_to_give() -> None:
    with pytest.raises(TypeError, match=r"texture: give a path or the file's bytes"):
        uploads.one_or_many(io.BytesIO(TEXTURE), "texture")  # type: ignore[arg-type]


@pytest.mark.parametrize(
    "name",
    ["a", "A", "0", "_", "-", "normal", "Normal_Map-2", "x" * 64, string.ascii_letters[:64]],
)
def test_companion_names_the_service_takes_are_kept(name: str) -> None:
    assert uploads.check_companion_name(name) == name


@pytest.mark.parametrize(
    "name",
    [
        "",
        "x" * 65,
        "a.b",
        "normal.png",
        "../evil",
        "a/b",
        "a\\b",
        "with space",
        "tab\t",
        "line\n",
        "\nline",
        "é",
        "ǅ",
        "٣",  # an Arabic-Indic digit: a digit to str.isdigit, not to the service
        "a:b",
        "a\x00",
    ],
)
def test_companion_names_the_service_would_reject_are_refused(name: str) -> None:
    with pytest.raises(ValidationError) as caught:
        uploads.check_companion_name(name)
    error = caught.value
    assert (error.code, error.field, error.status) == ("invalid_companion_name", "companion", None)
    assert repr(name) in error.detail


@pytest.mark.parametrize("name", [None, 7, b"normal", ["normal"]])
def test_a_companion_name_that_is_not_a_string_is_a_validation_error(name: object) -> None:
    with pytest.raises(ValidationError) as caught:
        uploads.check_companion_name(name)
    assert caught.value.code == "invalid_companion_name"


def test_companion_parts_are_named_after_the_companion_not_the_file(tmp_path: Path) -> None:
    sources = _sources(tmp_path, NORMAL)
    spec = proto.submit_request(
        TEXTURE,
        width=8,
        height=8,
        companions={f"map_{kind}": source for kind, source in sources.items()},
        options={},
        wait=0,
        idempotency_key=None,
    )
    companions = [p for p in spec.files if p[0] == "companion"]
    assert companions == [
        ("companion", (f"map_{kind}.png", NORMAL, "image/png")) for kind in sources
    ]


def test_a_bad_companion_name_builds_no_request(tmp_path: Path) -> None:
    missing = tmp_path / "missing.png"
    # The name is checked before its file is read: a validation error, not an OSError.
    with pytest.raises(ValidationError):
        proto.submit_request(
            TEXTURE,
            width=8,
            height=8,
            companions={"bad name": missing},
            options={},
            wait=0,
            idempotency_key=None,
        )


def test_output_names_keep_order_and_drop_repeats() -> None:
    assert uploads.output_names(["normals", "clusters", "normals"]) == ("normals", "clusters")
    assert uploads.output_names(iter(["b", "a", "b", "a"])) == ("b", "a")
    assert uploads.output_names(()) == ()
    assert uploads.output_names({"x": 1, "y": 2}) == ("x", "y")


def test_output_names_refuse_one_string_and_bad_names() -> None:
    with pytest.raises(TypeError, match="'normals'"):
        uploads.output_names("normals")
    with pytest.raises(ValidationError) as caught:
        uploads.output_names(["normals", "../x"])
    assert caught.value.code == "invalid_companion_name" and "'../x'" in caught.value.detail


@pytest.mark.parametrize("kind", KINDS)
def test_one_or_many_takes_one_image_as_a_list_of_it(tmp_path: Path, kind: str) -> None:
    source = _sources(tmp_path, TEXTURE)[kind]
    images = uploads.one_or_many(source, "texture")
    assert len(images) == 1
    assert uploads.read_source(images[0]) == uploads.read_source(source)
    if kind in {"bytearray", "memoryview"}:
        assert type(images[0]) is bytes  # a bytes-like is not a sequence of images
    else:
        assert images[0] is source


def test_one_or_many_keeps_a_sequence_in_order(tmp_path: Path) -> None:
    path = tmp_path / "second.jpg"
    path.write_bytes(ROUGH)
    assert uploads.one_or_many([TEXTURE, path, NORMAL], "texture") == [TEXTURE, path, NORMAL]
    assert uploads.one_or_many((TEXTURE,), "texture") == [TEXTURE]
    several = iter([NORMAL, TEXTURE])
    assert uploads.one_or_many(several, "texture") == [NORMAL, TEXTURE]  # type: ignore[arg-type]


@pytest.mark.parametrize("empty", [[], (), iter(())])
def test_one_or_many_refuses_no_image_naming_the_field(empty: Any) -> None:
    with pytest.raises(ValidationError) as caught:
        uploads.one_or_many(empty, "source_mask")
    error = caught.value
    assert (error.code, error.field, error.status) == ("missing_field", "source_mask", None)
    assert "source_mask" in error.detail


@pytest.mark.parametrize("kind", KINDS)
def test_images_of_refuses_a_lone_image(tmp_path: Path, kind: str) -> None:
    with pytest.raises(TypeError, match="layers"):
        uploads.images_of(_sources(tmp_path, TEXTURE)[kind], "layers")


def test_images_of_lists_a_sequence_or_an_iterator() -> None:
    assert uploads.images_of([TEXTURE, NORMAL], "layers") == [TEXTURE, NORMAL]
    assert uploads.images_of(iter((NORMAL,)), "layers") == [NORMAL]
    assert uploads.images_of([], "layers") == []


@pytest.mark.parametrize("kind", uploads.COMPANION_KINDS)
def test_every_companion_kind_of_the_service_is_taken(kind: str) -> None:
    companions = {"normal": NORMAL, "albedo": TEXTURE}
    kinds = {"normal": kind}
    checked = uploads.check_companion_kinds(kinds, companions)
    assert checked == {"normal": kind}
    checked["albedo"] = "hard"
    assert kinds == {"normal": kind}  # a copy is returned


def test_the_companion_kinds_are_the_documented_four() -> None:
    assert set(uploads.COMPANION_KINDS) == {"blend", "hard", "normal", "normal_dx"}


@pytest.mark.parametrize("kinds", [None, {}])
def test_no_companion_kinds_is_an_empty_mapping(kinds: dict[str, str] | None) -> None:
    assert uploads.check_companion_kinds(kinds, None) == {}
    assert uploads.check_companion_kinds(kinds, {"normal": NORMAL}) == {}


@pytest.mark.parametrize("companions", [None, {}, {"albedo": TEXTURE}])
def test_a_kind_for_a_companion_not_sent_is_refused(companions: dict[str, bytes] | None) -> None:
    with pytest.raises(ValidationError) as caught:
        uploads.check_companion_kinds({"normal": "normal"}, companions)
    error = caught.value
    assert (error.code, error.field) == ("invalid_companion", "companion_kinds")
    assert "'normal'" in error.detail


@pytest.mark.parametrize("kind", ["Blend", "normals", "", "soft", None])
def test_a_kind_the_service_does_not_take_is_refused(kind: Any) -> None:
    with pytest.raises(ValidationError) as caught:
        uploads.check_companion_kinds({"normal": kind}, {"normal": NORMAL})
    error = caught.value
    assert (error.code, error.field) == ("invalid_parameter", "companion_kinds")
    assert repr(kind) in error.detail and "'normal'" in error.detail
    for allowed in uploads.COMPANION_KINDS:
        assert allowed in error.detail
