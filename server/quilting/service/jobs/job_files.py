"""The uploaded files of a job besides its texture and companions, declared once: what a
submission holds once its form is read and what the job's input carries to its worker."""

from __future__ import annotations

import copy
from dataclasses import dataclass, field, fields
from typing import Any


@dataclass(kw_only=True)
class JobFiles:
    """The uploaded files of a job besides its texture and companions, as they came; what a
    submission (:class:`~quilting.service.forms.Submission`) and the job's input
    (:class:`JobInput`) both hold, declared once.

    Attributes
    ----------
    target : bytes or None
        The image a transfer renders or a matte lays textures on; None for a synthesis.
    source_mask : bytes or None
        Of the texture's size: black pixels are never used.
    layers : list of bytes
        A matte job's textures, bottom first (``texture`` is the first).
    silhouette, normals : bytes or None
        A matte job's silhouette and optional normal map, of the target's size.
    companion_kinds : dict of str to str
        How each companion is rendered (:func:`quilting.apply_layout`'s ``kind``: 'blend',
        'hard' or 'normal'), by name; a companion not named is 'blend'.
    mask : bytes or None
        A fill's mask, of its image's size: the pixels to fill.
    source : bytes or None
        A fill's texture, where its blocks come from instead of the image.
    examples : list of bytes
        Every texture of a synthesis or a Wang tile set made from several examples, in order
        (``texture`` is the first); empty for one texture, which is computed exactly as before
        examples existed.
    source_masks : list of bytes
        With several examples sent with source masks: one per example, in order
        (``source_mask`` is the first); else empty.
    example_companions : dict of str to list of bytes
        With several examples: each companion's map of every example, in order
        (``companions[name]`` is the first); else empty.
    trimaps, scribbles : list of (bytes or None)
        The trimaps and scribbles saying which of a photo is foreground, its alpha to be
        extracted first (:func:`quilting.extract_alpha`): one (or None) per example of a
        synthesis, per layer of a matte, or the one of an alpha extraction's photo (the
        ``texture``); empty when none was sent.
    """

    target: bytes | None = None
    source_mask: bytes | None = None
    layers: list[bytes] = field(default_factory=list)
    silhouette: bytes | None = None
    normals: bytes | None = None
    companion_kinds: dict[str, str] = field(default_factory=dict)
    mask: bytes | None = None
    source: bytes | None = None
    examples: list[bytes] = field(default_factory=list)
    source_masks: list[bytes] = field(default_factory=list)
    example_companions: dict[str, list[bytes]] = field(default_factory=dict)
    trimaps: list[bytes | None] = field(default_factory=list)
    scribbles: list[bytes | None] = field(default_factory=list)

    def job_files(self) -> dict[str, Any]:
        """The :class:`JobFiles` fields by name, each list and dict a copy of its own (what
        a job's input is made with from a submission)."""
        # deepcopy copies the lists and dicts; the bytes in them are immutable and shared.
        return {
            member.name: copy.deepcopy(getattr(self, member.name)) for member in fields(JobFiles)
        }
