"""The options of every job, with the choices their fields allow, as the upper layers see
them.

Each option is one field of a frozen dataclass (:class:`SynthesisOptions`,
:class:`TransferOptions`, :class:`MatteOptions`, :class:`TileOptions`; the fields they share
in :class:`QuiltOptions`); its ``metadata`` carries its documentation and limits, from which
the command line, the HTTP schema and the docs' tables are generated. The service and the
command line take them from here, never from :mod:`quilting.core.options`.
"""

from quilting.core.options import (
    BLENDS,
    CORRESPONDENCES,
    ERRORS,
    MATTE_MODES,
    MODES,
    TILE_BLENDS,
    TILEABLE,
    TRANSFER_MODES,
    Correspondence,
    MatteOptions,
    QuiltOptions,
    SynthesisOptions,
    TileOptions,
    TransferOptions,
)

__all__ = [
    "BLENDS",
    "CORRESPONDENCES",
    "ERRORS",
    "MATTE_MODES",
    "MODES",
    "TILEABLE",
    "TILE_BLENDS",
    "TRANSFER_MODES",
    "Correspondence",
    "MatteOptions",
    "QuiltOptions",
    "SynthesisOptions",
    "TileOptions",
    "TransferOptions",
]
