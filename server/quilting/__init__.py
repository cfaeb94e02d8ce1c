"""quilting: texture synthesis and transfer by image quilting (Efros & Freeman 2001).

>>> import numpy as np, quilting
>>> texture = quilting.read_image("gravel.png")            # doctest: +SKIP
>>> result = quilting.synthesize(texture, (512, 512), seed=7)  # doctest: +SKIP
>>> quilting.write_image("out.png", result.image)          # doctest: +SKIP
"""

from quilting.api import (
    Filled,
    MatteResult,
    Tiled,
    extend,
    fill,
    make_tileable,
    matte,
    synthesize,
    transfer,
    wang_tiles,
    warm_up,
)
from quilting.core.budget import (
    BASE_BYTES,
    Budget,
    Estimate,
    JobTooLargeError,
    estimate_extract,
    estimate_fill,
    estimate_synthesis,
    estimate_tile,
    estimate_transfer,
    estimate_wang,
)
from quilting.core.errors import (
    BackendError,
    CancelledError,
    ImageDecodeError,
    ImageTooLargeError,
    InvalidImageError,
    InvalidParameterError,
    LayoutError,
    QuiltingError,
)
from quilting.core.fill import check_fill, hole_box, hole_of
from quilting.core.fill_layout import FillLayout, is_fill_layout
from quilting.core.layout import COMPANION_KINDS, Layout, apply_layout, check_companion_kind
from quilting.core.matte import estimate_matte
from quilting.core.options import (
    AlphaOptions,
    ExtendOptions,
    FillOptions,
    MatteOptions,
    QuiltOptions,
    SynthesisOptions,
    TileOptions,
    TransferOptions,
    WangOptions,
)
from quilting.core.sources import TRANSFORMS
from quilting.core.stats import SynthesisStats, seam_mask
from quilting.core.synthesis import Result
from quilting.core.trimap import Extracted, InvalidTrimapError
from quilting.core.wang import WangTiles
from quilting.extract import MattingUnavailableError, check_extract, extract_alpha
from quilting.extract import available as matting_available
from quilting.io import read_image, write_image

__version__ = "0.1.0"

__all__ = [
    "BASE_BYTES",
    "COMPANION_KINDS",
    "TRANSFORMS",
    "AlphaOptions",
    "BackendError",
    "Budget",
    "CancelledError",
    "Estimate",
    "ExtendOptions",
    "Extracted",
    "FillLayout",
    "FillOptions",
    "Filled",
    "ImageDecodeError",
    "ImageTooLargeError",
    "InvalidImageError",
    "InvalidParameterError",
    "InvalidTrimapError",
    "JobTooLargeError",
    "Layout",
    "LayoutError",
    "MatteOptions",
    "MatteResult",
    "MattingUnavailableError",
    "QuiltOptions",
    "QuiltingError",
    "Result",
    "SynthesisOptions",
    "SynthesisStats",
    "TileOptions",
    "Tiled",
    "TransferOptions",
    "WangOptions",
    "WangTiles",
    "__version__",
    "apply_layout",
    "check_companion_kind",
    "check_extract",
    "check_fill",
    "estimate_extract",
    "estimate_fill",
    "estimate_matte",
    "estimate_synthesis",
    "estimate_tile",
    "estimate_transfer",
    "estimate_wang",
    "extend",
    "extract_alpha",
    "fill",
    "hole_box",
    "hole_of",
    "is_fill_layout",
    "make_tileable",
    "matte",
    "matting_available",
    "read_image",
    "seam_mask",
    "synthesize",
    "transfer",
    "wang_tiles",
    "warm_up",
    "write_image",
]
