"""The Python API's option keywords, generated from the options dataclasses.

Every public entry point takes an options object (``options=``) and, for convenience, any of
its fields as a keyword that overrides it. Those keywords are not written out in the function:
:func:`option_keywords` gives the function a signature (what ``help()``, ``inspect`` and
editors show) and a numpydoc "Other Parameters" section made from the dataclass's fields, so
an option added to the dataclass reaches the API, with its documentation, by itself.
"""

from __future__ import annotations

import inspect
import textwrap
from collections.abc import Callable
from dataclasses import MISSING, Field, fields
from typing import Any, TypeVar

from quilting.core.options import (
    AlphaOptions,
    FillOptions,
    MatteOptions,
    QuiltOptions,
    TileOptions,
    WangOptions,
)

Options = (
    type[QuiltOptions]
    | type[MatteOptions]
    | type[TileOptions]
    | type[FillOptions]
    | type[WangOptions]
    | type[AlphaOptions]
)
F = TypeVar("F", bound=Callable[..., Any])

#: Where the generated section goes in a docstring written for :func:`option_keywords`.
PLACEHOLDER = "{option_keywords}"

#: Fields that take more than the dataclass's type at the API (an engine object).
_WIDER = {"backend": "str | CostBackend"}


def option_keywords(options: Options) -> Callable[[F], F]:
    """Give ``func`` (which takes ``**overrides``) one keyword-only parameter per field of
    ``options`` in its signature and an "Other Parameters" section at the docstring's
    :data:`PLACEHOLDER`.

    The function itself still receives the keywords as ``**overrides`` and passes them to
    ``options.resolve``, which refuses a name that is no field.
    """

    def decorate(func: F) -> F:
        signature = inspect.signature(func)
        params = [
            p for p in signature.parameters.values() if p.kind is not inspect.Parameter.VAR_KEYWORD
        ]
        taken = {p.name for p in params}
        params += [
            inspect.Parameter(
                f.name,
                inspect.Parameter.KEYWORD_ONLY,
                default=_default(f),
                annotation=_WIDER.get(f.name, f.type),
            )
            for f in fields(options)
            if f.name not in taken
        ]
        func.__signature__ = signature.replace(parameters=params)  # type: ignore[attr-defined]
        if func.__doc__ and PLACEHOLDER in func.__doc__:
            func.__doc__ = func.__doc__.replace(PLACEHOLDER, _section(options, taken))
        return func

    return decorate


def _section(options: Options, taken: set[str]) -> str:
    """The numpydoc "Other Parameters" section of ``options``'s fields, indented for a
    function's docstring (4 spaces)."""
    lines = [
        "Other Parameters",
        "----------------",
        f"Any field of :class:`~quilting.{options.__name__}`, replacing the one in ``options``:",
        "",
    ]
    for f in fields(options):
        if f.name in taken:
            continue
        default = _default(f)
        given = "required" if default is inspect.Parameter.empty else f"default {default!r}"
        lines.append(f"{f.name} : {_kind(f)}, {given}")
        doc = f.metadata.get("doc", "")
        # Unbroken at hyphens: "multi-level" must not come out as "multi- level".
        lines += textwrap.wrap(
            doc, 88, initial_indent="    ", subsequent_indent="    ", break_on_hyphens=False
        )
    return "\n".join(lines[:1]) + "\n" + textwrap.indent("\n".join(lines[1:]), "    ")


def _default(f: Field[Any]) -> Any:
    """A field's default as the signature shows it (a factory's value; none: required)."""
    if f.default is not MISSING:
        return f.default
    if f.default_factory is not MISSING:
        return f.default_factory()
    return inspect.Parameter.empty


def _kind(f: Field[Any]) -> str:
    """A field's type as numpydoc writes it: its choices as a set, else its annotation."""
    if f.name in _WIDER:
        return _WIDER[f.name].replace(" | ", " or ")
    choices = f.metadata.get("choices")
    if choices is not None:
        named = [repr(c) for c in choices if c is not None]
        return "{" + ", ".join(named) + "}" + (" or None" if None in choices else "")
    return str(f.type).replace(" | None", " or None").replace(" | ", " or ")
