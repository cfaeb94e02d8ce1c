"""A job's input: its uploaded files as they came (compressed: the worker decodes them), its
options as JSON, the output's size and the pixel limits it was accepted under; and the byte
format it crosses processes in (the distributed queue, :meth:`JobInput.to_bytes`): a JSON
header and the files, never a pickle, so a queue's contents cannot run code in a worker.
"""

from __future__ import annotations

import json
from dataclasses import MISSING, asdict, dataclass, field, fields
from typing import Any

from quilting import AlphaOptions
from quilting.options import (
    ExtendOptions,
    FillOptions,
    MatteOptions,
    QuiltOptions,
    SynthesisOptions,
    TransferOptions,
    WangOptions,
)
from quilting.service.jobs.job_files import JobFiles
from quilting.service.settings import Settings

#: What a matte job makes beside its result: the normals used and the patches.
MATTE_OUTPUTS = ("normals", "clusters")

#: The operation of ``POST /extract-alpha``: an RGBA texture from a photo and its trimap or
#: scribbles (nothing quilted).
EXTRACT = "extract_alpha"

#: The options class of each operation: a job's ``options`` is one of these as JSON, whole.
OPTIONS: dict[
    str, type[QuiltOptions] | type[FillOptions] | type[WangOptions] | type[AlphaOptions]
] = {
    "synthesize": SynthesisOptions,
    "transfer": TransferOptions,
    "matte": MatteOptions,
    "fill": FillOptions,
    "extend": ExtendOptions,
    "wang_tiles": WangOptions,
    EXTRACT: AlphaOptions,
}


@dataclass(frozen=True)
class PixelLimits:
    """The pixel limits a job's uploads were accepted under, which its worker decodes them
    under again (settings of the same names).

    Attributes
    ----------
    max_input_pixels : int
        Most pixels an uploaded image may declare.
    max_output_pixels : int
        Most output pixels; also the limit of an upload whose size is the output's (a
        target, a silhouette, the image of ``/tile``) when it is the tighter one.
    max_side : int
        Longest output side in pixels.
    """

    max_input_pixels: int = 25_000_000
    max_output_pixels: int = 67_108_864
    max_side: int = 16384

    @classmethod
    def of(cls, settings: Settings) -> PixelLimits:
        """The limits of ``settings``."""
        return cls(settings.max_input_pixels, settings.max_output_pixels, settings.max_side)

    def input_sized(self) -> tuple[int, str]:
        """The pixel limit of any other upload (a texture, a companion, a layer, a mask), and
        the setting's name."""
        return self.max_input_pixels, "max_input_pixels"

    def output_sized(self) -> tuple[int, str]:
        """The pixel limit of an input whose size is also the output's: whichever of the input
        and output limits is tighter, and the setting's name."""
        if self.max_output_pixels <= self.max_input_pixels:
            return self.max_output_pixels, "max_output_pixels"
        return self.max_input_pixels, "max_input_pixels"


#: Magic first bytes of :meth:`JobInput.to_bytes` (the format's version is its last digit).
_INPUT_MAGIC = b"quilting-job-input-1\n"
_ROLES = frozenset(
    {
        "texture",
        "companion",
        "target",
        "source_mask",
        "layer",
        "silhouette",
        "normals",
        "mask",
        "source",
        "example",
        "example_mask",
        "example_companion",
        "trimap",
        "scribbles",
    }
)


@dataclass
class JobInput(JobFiles):
    """What a job computes from: the uploaded files as they came (compressed), and the engine
    keyword arguments.

    The API process keeps a queued job at about the size of its uploads: the images are
    decoded by the worker that runs the job (:func:`quilting.service.uploads.decode`), under
    the job's time and memory limits and the pixel ``limits`` the uploads were checked
    against. The other files are the :class:`JobFiles` fields (keywords).

    Attributes
    ----------
    texture : bytes
        The sample texture's file (a matte job's first layer; a fill's or an extension's
        image).
    companions : dict of str to bytes
        Companion maps of the texture's size, quilted with the result's layout (a fill's and
        an extension's: filled the way the image is), by name.
    options : dict
        The job's options object as JSON (:meth:`~quilting.SynthesisOptions.to_dict` of the
        operation's options class); :meth:`engine_options` makes the object again.
    width, height : int
        Output size (a transfer's and a matte's is its target's, a fill's its image's, an
        extension's its image's grown by the margins).
    operation : str
        ``"synthesize"``, ``"transfer"``, ``"matte"``, ``"fill"``, ``"extend"``,
        ``"wang_tiles"`` or ``"extract_alpha"``: which engine entry point computes the job.
    limits : PixelLimits
        The pixel limits the files are decoded under.
    """

    texture: bytes
    companions: dict[str, bytes]
    options: dict[str, Any]
    width: int
    height: int
    operation: str = "synthesize"
    limits: PixelLimits = field(default_factory=PixelLimits)

    def __setstate__(self, state: dict[str, Any]) -> None:
        # A pickle made by an older build (a job handed to a worker process during an
        # upgrade) lacks the files added since (companion kinds, a fill's mask and source,
        # several examples, trimaps and scribbles): each takes its default, none sent.
        for member in fields(JobFiles):
            if member.name not in state:
                factory = member.default_factory
                state[member.name] = member.default if factory is MISSING else factory()
        self.__dict__.update(state)

    def engine_options(self) -> QuiltOptions | FillOptions | WangOptions | AlphaOptions:
        """The options object the job runs with, made from its JSON (validated once more:
        a job read from Redis may come from another build)."""
        return OPTIONS[self.operation].resolve(None, self.options, caller=self.operation)

    def kind_of(self, name: str) -> str:
        """How the companion ``name`` is rendered ('blend' unless the job says otherwise)."""
        return self.companion_kinds.get(name, "blend")

    @property
    def textures(self) -> list[bytes]:
        """Every example texture, in order (one for a job of one texture)."""
        return list(self.examples) or [self.texture]

    @property
    def masks(self) -> list[bytes | None]:
        """The source mask of each example, in order (None where there is none)."""
        if self.source_masks:
            return list(self.source_masks)
        return [self.source_mask, *[None] * (len(self.textures) - 1)]

    def marks(self, count: int) -> list[tuple[bytes | None, bytes | None]]:
        """``(trimap, scribbles)`` of each of ``count`` photos (the examples, the layers, the
        one photo), in order; ``(None, None)`` for one without."""

        def each(found: list[bytes | None]) -> list[bytes | None]:
            return list(found) if found else [None] * count

        return list(zip(each(self.trimaps), each(self.scribbles), strict=True))

    @property
    def extracting(self) -> bool:
        """Whether an alpha is extracted from any photo of the job."""
        return any(data is not None for data in [*self.trimaps, *self.scribbles])

    def maps_of(self, name: str) -> list[bytes]:
        """The companion ``name``'s map of every example, in order."""
        return list(self.example_companions.get(name) or [self.companions[name]])

    @property
    def outputs(self) -> list[str]:
        """Names of the images the job makes beside its result (``/result/{name}``)."""
        return list(MATTE_OUTPUTS) if self.operation == "matte" else list(self.companions)

    def files(self) -> list[tuple[str, str, bytes]]:
        """``(role, name, bytes)`` of every uploaded file, in a fixed order (the texture
        first; a companion's name is its own, a layer's its index, others' empty)."""
        found: list[tuple[str, str, bytes]] = [("texture", "", self.texture)]
        found += [("companion", name, data) for name, data in self.companions.items()]
        for role in ("target", "source_mask", "silhouette", "normals", "mask", "source"):
            data = getattr(self, role)
            if data is not None:
                found.append((role, "", data))
        # The first layer is the texture: kept once; so is the first example's of each list.
        found += [("layer", str(k), data) for k, data in enumerate(self.layers) if k > 0]
        found += [("example", str(k), data) for k, data in enumerate(self.examples) if k > 0]
        found += [
            ("example_mask", str(k), data) for k, data in enumerate(self.source_masks) if k > 0
        ]
        for name, maps in self.example_companions.items():
            found += [("example_companion", f"{k}/{name}", d) for k, d in enumerate(maps) if k > 0]
        for role, marks in (("trimap", self.trimaps), ("scribbles", self.scribbles)):
            found += [(role, str(k), data) for k, data in enumerate(marks) if data is not None]
        return found

    @property
    def nbytes(self) -> int:
        """Bytes of the uploaded files the input holds (what a queued job costs to keep)."""
        return sum(len(data) for _, _, data in self.files())

    def to_bytes(self) -> bytes:
        """The input as one byte string: a JSON header (options, size, limits, the files'
        roles and lengths), then the files' bytes. No pickle: reading it runs no code."""
        files = self.files()
        header = {
            "options": self.options,
            "width": self.width,
            "height": self.height,
            "operation": self.operation,
            "limits": asdict(self.limits),
            "layers": len(self.layers),
            "examples": len(self.examples),
            "companion_kinds": dict(self.companion_kinds),
            # The lists' lengths: a photo without a map is a gap, not a file.
            "trimaps": len(self.trimaps),
            "scribbles": len(self.scribbles),
            "files": [[role, name, len(data)] for role, name, data in files],
        }
        text = json.dumps(header).encode()
        return b"".join(
            [_INPUT_MAGIC, len(text).to_bytes(4, "big"), text, *(data for _, _, data in files)]
        )

    @classmethod
    def from_bytes(cls, data: bytes) -> JobInput:
        """The input :meth:`to_bytes` wrote.

        Raises
        ------
        ValueError
            ``data`` is not what :meth:`to_bytes` writes (another format, or cut short).
        """
        try:
            return cls._parse(memoryview(data))
        except (KeyError, TypeError, IndexError) as exc:
            raise ValueError(f"a job input's header is malformed ({exc!r})") from None

    @classmethod
    def _parse(cls, view: memoryview) -> JobInput:
        if bytes(view[: len(_INPUT_MAGIC)]) != _INPUT_MAGIC:
            raise ValueError("not a quilting job input (unknown first bytes)")
        at = len(_INPUT_MAGIC)
        size = int.from_bytes(view[at : at + 4], "big")
        at += 4
        try:
            header = json.loads(bytes(view[at : at + size]))
        except ValueError as exc:
            raise ValueError(f"a job input's header is not JSON: {exc}") from None
        at += size
        found: dict[str, bytes] = {}
        companions: dict[str, bytes] = {}
        layers: dict[int, bytes] = {}
        numbered: dict[str, dict[int, bytes]] = {
            "example": {},
            "example_mask": {},
            "trimap": {},
            "scribbles": {},
        }
        more_maps: dict[str, dict[int, bytes]] = {}
        for role, name, length in header["files"]:
            if role not in _ROLES or not isinstance(length, int) or length < 0:
                raise ValueError(f"a job input names an unknown file {role!r}")
            blob = bytes(view[at : at + length])
            if len(blob) != length:
                raise ValueError("a job input is cut short")
            at += length
            if role == "companion":
                companions[name] = blob
            elif role == "layer":
                layers[int(name)] = blob
            elif role in numbered:
                numbered[role][int(name)] = blob
            elif role == "example_companion":
                index, _, companion = name.partition("/")
                more_maps.setdefault(companion, {})[int(index)] = blob
            else:
                found[role] = blob
        if at != len(view):
            raise ValueError("a job input has bytes after its files")
        texture = found["texture"]
        count = int(header["layers"])
        # Absent from inputs written before several examples: one texture.
        examples = int(header.get("examples") or 0)

        def listed(first: bytes | None, more: dict[int, bytes]) -> list[bytes]:
            if not examples or first is None or not more:
                return []
            return [first, *(more[k] for k in range(1, examples))]

        return cls(
            texture=texture,
            companions=companions,
            options=header["options"],
            width=int(header["width"]),
            height=int(header["height"]),
            target=found.get("target"),
            operation=str(header["operation"]),
            source_mask=found.get("source_mask"),
            layers=[texture, *(layers[k] for k in range(1, count))] if count else [],
            silhouette=found.get("silhouette"),
            normals=found.get("normals"),
            mask=found.get("mask"),
            source=found.get("source"),
            limits=PixelLimits(**header["limits"]),
            # Absent from inputs written before companions had kinds: all were 'blend'.
            companion_kinds={
                str(k): str(v) for k, v in dict(header.get("companion_kinds") or {}).items()
            },
            examples=listed(texture, numbered["example"]),
            source_masks=listed(found.get("source_mask"), numbered["example_mask"]),
            example_companions={
                name: maps
                for name, more in more_maps.items()
                if (maps := listed(companions[name], more))
            },
            # Absent from inputs written before alpha extraction: none.
            trimaps=[numbered["trimap"].get(k) for k in range(int(header.get("trimaps") or 0))],
            scribbles=[
                numbered["scribbles"].get(k) for k in range(int(header.get("scribbles") or 0))
            ],
        )
