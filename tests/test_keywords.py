"""The option keywords the public entry points get from the options dataclasses.

Covers :mod:`quilting._keywords`: :func:`~quilting._keywords.option_keywords` and the numpydoc
"Other Parameters" section it writes (``_section``, ``_kind``).

The decorated functions are found by reading the source of :mod:`quilting.api` and
:mod:`quilting.extract` (every ``@option_keywords(Cls)``), so a new entry point is checked
without being listed here. For each: the placeholder is gone, the section lists every field
once, in the dataclass's order, with its type and default as written by ``_kind`` and ``repr``
and its whole documentation; the section is laid out at the docstring's indentation; the
signature offers exactly the documented keywords; an unknown or misspelt keyword, or one of
another operation's options, is refused with a ``TypeError`` naming the function and the
closest field before any input is looked at; and a keyword reaches the options (``fill`` and
``extend``; ``synthesize`` and ``make_tileable`` are in tests/test_entry_points.py). A toy
function and a toy frozen dataclass check the decorator itself: parameters the function
names are left out, fields without a default or a documentation, a docstring without the
placeholder, and no docstring.
"""

from __future__ import annotations

import ast
import dataclasses
import inspect
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import quilting
from quilting import _keywords
from quilting._keywords import PLACEHOLDER, option_keywords

SERVER = Path(quilting.__file__).resolve().parent
HEADER = "\n    Other Parameters\n    ----------------\n"
ENTRY = re.compile(r"^    (?P<name>\w+) : (?P<kind>.+), default (?P<default>.+)$")


def _decorated() -> list[tuple[str, str, str]]:
    """(module, function, options class) of every ``@option_keywords(Cls)`` in the sources."""
    found = []
    for module in ("api", "extract"):
        tree = ast.parse((SERVER / f"{module}.py").read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if not isinstance(node, ast.FunctionDef):
                continue
            for deco in node.decorator_list:
                if (
                    isinstance(deco, ast.Call)
                    and isinstance(deco.func, ast.Name)
                    and deco.func.id == "option_keywords"
                ):
                    arg = deco.args[0]
                    assert isinstance(arg, ast.Name)
                    found.append((module, node.name, arg.id))
    return found


DECORATED = _decorated()
IDS = [name for _, name, _ in DECORATED]


def _target(module: str, name: str, cls_name: str) -> tuple[Callable[..., Any], type]:
    """The public function (from the ``quilting`` package) and its options class."""
    func = getattr(quilting, name)
    assert func is getattr(getattr(quilting, module), name)
    return func, getattr(quilting, cls_name)


def _section(doc: str) -> list[str]:
    """The generated section's lines: header, underline, intro, blank, then the fields, up
    to the blank line that ends it."""
    assert doc.count(HEADER) == 1
    lines = doc[doc.index(HEADER) + 1 :].split("\n")
    end = lines.index("", 4)  # the intro is followed by one blank line, the fields by one
    return lines[:end]


def _entries(section: list[str]) -> list[tuple[str, str, str, str]]:
    """(name, kind, default, description) of each field listed in a section."""
    entries: list[tuple[str, str, str, str]] = []
    for line in section[4:]:
        match = ENTRY.match(line)
        if match:
            entries.append((match["name"], match["kind"], match["default"], ""))
        else:
            assert line.startswith(" " * 8) and line[8] != " ", line
            name, kind, default, text = entries[-1]
            entries[-1] = (name, kind, default, f"{text} {line.strip()}".strip())
    return entries


def _expected_kind(f: dataclasses.Field[Any]) -> str:
    """A field's type as the section should name it, from its metadata and annotation."""
    if f.name == "backend":  # the API also takes an engine object
        return "str or CostBackend"
    choices = f.metadata.get("choices")
    if choices is not None:
        named = "{" + ", ".join(repr(c) for c in choices if c is not None) + "}"
        return named + (" or None" if None in choices else "")
    assert isinstance(f.type, str)  # the options modules use postponed annotations
    return f.type.replace(" | ", " or ")


def _bare(text: str) -> str:
    """Text without any whitespace (the section wraps lines, also after a hyphen)."""
    return "".join(text.split())


def _call_args(func: Callable[..., Any]) -> tuple[list[Any], dict[str, Any]]:
    """None for every required parameter: inputs no entry point accepts."""
    positional: list[Any] = []
    keywords: dict[str, Any] = {}
    for p in inspect.signature(func).parameters.values():
        if p.default is not inspect.Parameter.empty:
            continue
        if p.kind is inspect.Parameter.KEYWORD_ONLY:
            keywords[p.name] = None
        else:
            positional.append(None)
    return positional, keywords


# --- the entry points -----------------------------------------------------------------------


def test_the_decorated_entry_points_are_found() -> None:
    names = {name for _, name, _ in DECORATED}
    assert {"synthesize", "transfer", "fill", "extend", "make_tileable", "matte"} <= names
    assert {"wang_tiles", "extract_alpha"} <= names
    assert len(names) == len(DECORATED)  # one decorator each
    for module, name, cls_name in DECORATED:
        func, cls = _target(module, name, cls_name)
        assert dataclasses.is_dataclass(cls), cls_name
        assert callable(func)


def test_no_public_docstring_keeps_the_placeholder() -> None:
    for name in quilting.__all__:
        doc = getattr(getattr(quilting, name), "__doc__", None) or ""
        assert PLACEHOLDER not in doc, name
    for module in (quilting.api, quilting.extract):
        for name, value in vars(module).items():
            if callable(value) and getattr(value, "__module__", None) == module.__name__:
                assert PLACEHOLDER not in (value.__doc__ or ""), f"{module.__name__}.{name}"


@pytest.mark.parametrize(("module", "name", "cls_name"), DECORATED, ids=IDS)
def test_section_lists_every_field_once_with_its_kind_default_and_doc(
    module: str, name: str, cls_name: str
) -> None:
    func, cls = _target(module, name, cls_name)
    section = _section(func.__doc__ or "")
    # The class it names is the one behind the keywords, reachable as written.
    assert section[2] == (
        f"    Any field of :class:`~quilting.{cls_name}`, replacing the one in ``options``:"
    )
    assert getattr(quilting, cls_name) is cls
    entries = _entries(section)
    fields = dataclasses.fields(cls)
    assert [e[0] for e in entries] == [f.name for f in fields]  # each once, in order
    for (_, kind, default, text), f in zip(entries, fields, strict=True):
        assert kind == _expected_kind(f), f.name
        assert default == repr(f.default), f.name
        assert _bare(text) == _bare(f.metadata["doc"]), f.name
    # Outside the section no field is documented as a parameter.
    rest = (func.__doc__ or "").replace("\n".join(section), "")
    for f in fields:
        assert f"\n    {f.name} : " not in rest, f.name


@pytest.mark.parametrize(("module", "name", "cls_name"), DECORATED, ids=IDS)
def test_section_is_laid_out_at_the_docstring_indent(module: str, name: str, cls_name: str) -> None:
    func, _ = _target(module, name, cls_name)
    doc = func.__doc__ or ""
    section = _section(doc)
    assert section[0] == "    Other Parameters"
    assert section[1] == "    " + "-" * len("Other Parameters")
    assert section[3] == ""
    for line in section[4:]:
        assert line == line.rstrip(), repr(line)
        assert len(line) <= 4 + 4 + 88, repr(line)  # wrapped at 88, then indented
    # After cleaning the indentation the section is a numpydoc one, followed by the rest.
    cleaned = inspect.cleandoc(doc)
    assert "\nOther Parameters\n----------------\nAny field of" in cleaned
    after = doc[doc.index(HEADER) + 1 :].split("\n")[len(section) :]
    assert after[0] == "" and after[1].strip() in ("Returns", "Raises")


@pytest.mark.parametrize(("module", "name", "cls_name"), DECORATED, ids=IDS)
def test_signature_offers_exactly_the_documented_keywords(
    module: str, name: str, cls_name: str
) -> None:
    func, cls = _target(module, name, cls_name)
    params = inspect.signature(func).parameters
    assert not any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values())
    generated = [p for p in params.values() if p.name in {f.name for f in dataclasses.fields(cls)}]
    documented = [e[0] for e in _entries(_section(func.__doc__ or ""))]
    assert [p.name for p in generated] == documented
    # The generated ones come after the function's own, keyword-only.
    assert list(params)[-len(generated) :] == documented
    assert all(p.kind is inspect.Parameter.KEYWORD_ONLY for p in generated)
    if "backend" in params:
        assert params["backend"].annotation == "str | CostBackend"


@pytest.mark.parametrize(("module", "name", "cls_name"), DECORATED, ids=IDS)
def test_every_documented_keyword_is_accepted(module: str, name: str, cls_name: str) -> None:
    func, cls = _target(module, name, cls_name)
    args, keywords = _call_args(func)
    defaults = {f.name: f.default for f in dataclasses.fields(cls)}
    # The keywords pass; what is refused is the inputs (None), which are looked at later.
    with pytest.raises(Exception) as caught:
        func(*args, **keywords, **defaults)
    assert "keyword argument" not in str(caught.value)
    assert isinstance(caught.value, quilting.QuiltingError), repr(caught.value)


@pytest.mark.parametrize(("module", "name", "cls_name"), DECORATED, ids=IDS)
def test_a_misspelt_keyword_is_refused_first_naming_the_closest_field(
    module: str, name: str, cls_name: str
) -> None:
    func, cls = _target(module, name, cls_name)
    args, keywords = _call_args(func)
    for f in dataclasses.fields(cls):
        wrong = f.name + f.name[-1]
        pattern = (
            rf"^{name}\(\) got an unexpected keyword argument '{wrong}'; did you mean "
            rf"'{f.name}'\?$"
        )
        # Refused before the inputs (None, which every entry point refuses) are read.
        with pytest.raises(TypeError, match=pattern):
            func(*args, **keywords, **{wrong: f.default})


@pytest.mark.parametrize(("module", "name", "cls_name"), DECORATED, ids=IDS)
def test_another_operations_option_is_refused(module: str, name: str, cls_name: str) -> None:
    func, cls = _target(module, name, cls_name)
    args, keywords = _call_args(func)
    own = {f.name for f in dataclasses.fields(cls)}
    others = {
        f.name
        for other in (quilting.SynthesisOptions, quilting.TransferOptions, quilting.ExtendOptions)
        for f in dataclasses.fields(other)
    } - own
    assert others
    for other in sorted(others):
        with pytest.raises(TypeError, match=rf"^{name}\(\) got an unexpected keyword argument"):
            func(*args, **keywords, **{other: 1})


# --- _kind ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("cls", "name", "kind"),
    [
        (quilting.SynthesisOptions, "block", "int"),
        (quilting.SynthesisOptions, "overlap", "int or None"),
        (quilting.SynthesisOptions, "tolerance", "float"),
        (quilting.SynthesisOptions, "blend", "{'none', 'poisson'}"),
        (quilting.SynthesisOptions, "tileable", "{'both', 'x', 'y'} or None"),
        (quilting.SynthesisOptions, "backend", "str or CostBackend"),
        (quilting.SynthesisOptions, "transforms", "str"),
        (quilting.SynthesisOptions, "weights", "tuple[float, ...] or None"),
        (quilting.SynthesisOptions, "exclude_colors", "tuple[ColorRange, ...]"),
        (quilting.TransferOptions, "alpha", "float or None"),
        (quilting.TransferOptions, "remap", "bool"),
        (quilting.MatteOptions, "light", "tuple[float, float, float] or None"),
        (quilting.FillOptions, "backend", "str or CostBackend"),
        (quilting.AlphaOptions, "foreground", "{'ml', 'photo'}"),
    ],
    ids=lambda x: getattr(x, "__name__", str(x)),
)
def test_kind_names_choices_as_a_set_and_unions_with_or(cls: type, name: str, kind: str) -> None:
    (f,) = [f for f in dataclasses.fields(cls) if f.name == name]
    assert _keywords._kind(f) == kind


# --- keywords reach the options -------------------------------------------------------------


def _picture() -> tuple[np.ndarray, np.ndarray]:
    """A 40x40 RGB noise image with a 12x12 hole in the middle."""
    image = np.random.default_rng(7).integers(0, 256, (40, 40, 3), dtype=np.uint8)
    hole = np.zeros((40, 40), dtype=bool)
    hole[14:26, 14:26] = True
    return image, hole


def test_fill_keywords_replace_the_options_fields() -> None:
    image, hole = _picture()
    base = quilting.FillOptions(block=8, blend="none", tolerance=10.0, seed=1)
    by_object = quilting.fill(image, hole, dataclasses.replace(base, seed=3))
    by_keyword = quilting.fill(image, hole, base, seed=3)
    only_keywords = quilting.fill(image, hole, block=8, blend="none", tolerance=10.0, seed=3)
    assert by_keyword.image.tobytes() == by_object.image.tobytes()
    assert only_keywords.image.tobytes() == by_object.image.tobytes()
    # The seed matters here, so the equalities say the keyword was used.
    assert quilting.fill(image, hole, base).image.tobytes() != by_object.image.tobytes()


def test_extend_keywords_replace_the_options_fields() -> None:
    image, _ = _picture()
    options = quilting.ExtendOptions(block=8, blend="none", top=5, left=3)
    by_object = quilting.extend(image, options)
    by_keyword = quilting.extend(
        image, quilting.ExtendOptions(block=8), blend="none", top=5, left=3
    )
    assert by_object.image.shape == (45, 43, 3)
    assert by_keyword.image.tobytes() == by_object.image.tobytes()
    assert np.array_equal(by_keyword.image[5:, 3:], image)
    wider = quilting.extend(image, options, right=4)
    assert wider.image.shape == (45, 47, 3)


def test_an_out_of_range_keyword_names_its_field() -> None:
    image, hole = _picture()
    with pytest.raises(quilting.InvalidParameterError) as caught:
        quilting.fill(image, hole, quilting.FillOptions(block=8), search_scale=-1)
    assert caught.value.parameter == "search_scale"


# --- the decorator on a toy -----------------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class Toy:
    """A toy options class: a field of each sort the section writes."""

    width: int = field(default=3, metadata={"doc": "How wide the toy is, in whole bricks."})
    colour: str | None = field(
        default=None, metadata={"doc": "Its paint.", "choices": (None, "red", "blue")}
    )
    ratio: float = 0.5  # no documentation
    count: int = field(default=1, metadata={"doc": "Named by the function itself."})


@dataclass(frozen=True, kw_only=True)
class Needed:
    """A toy options class with a field the caller must give."""

    label: str = field(metadata={"doc": "No default."})
    size: int = 2


TOY_DOC = """Make a toy.

    Parameters
    ----------
    texture : object
    count : int
        The function's own parameter, documented here.

    {option_keywords}

    Returns
    -------
    dict
    """


def _decorate(func: Callable[..., Any], options: type = Toy) -> Callable[..., Any]:
    return option_keywords(options)(func)


def test_toy_signature_adds_the_fields_the_function_does_not_name() -> None:
    def toy(texture: object, count: int = 9, *, strict: bool = False, **overrides: Any) -> Any:
        return {"texture": texture, "count": count, "strict": strict, **overrides}

    toy.__doc__ = TOY_DOC
    decorated = _decorate(toy)
    assert decorated is toy  # decorated in place, still the same callable
    params = inspect.signature(decorated).parameters
    assert list(params) == ["texture", "count", "strict", "width", "colour", "ratio"]
    assert params["count"].default == 9  # the function's own, not the field's 1
    assert params["count"].kind is inspect.Parameter.POSITIONAL_OR_KEYWORD
    assert params["width"].default == 3 and params["width"].annotation == "int"
    assert params["colour"].annotation == "str | None"
    assert all(params[n].kind is inspect.Parameter.KEYWORD_ONLY for n in ("width", "ratio"))
    # The function itself still takes the keywords as **overrides.
    assert decorated("t", width=4) == {"texture": "t", "count": 9, "strict": False, "width": 4}


def test_toy_field_without_a_default_is_a_required_keyword() -> None:
    def toy(**overrides: Any) -> None:
        del overrides

    params = inspect.signature(_decorate(toy, Needed)).parameters
    assert params["label"].default is inspect.Parameter.empty
    assert params["label"].kind is inspect.Parameter.KEYWORD_ONLY
    assert params["size"].default == 2


@dataclass(frozen=True, kw_only=True)
class Grown:
    """A toy options class whose fields need a factory or a value, and a hyphenated doc."""

    label: str = field(metadata={"doc": "No default."})
    sizes: tuple[int, ...] = field(default_factory=tuple, metadata={"doc": "Made fresh."})
    mode: str = field(
        default="a",
        metadata={"doc": "A long doc " + "word " * 13 + "multi-level split-free term."},
    )


def test_toy_section_writes_required_factory_defaults_and_keeps_hyphenated_words() -> None:
    def toy(**overrides: Any) -> None:
        del overrides

    toy.__doc__ = "Make a toy.\n\n    {option_keywords}\n\n    Returns\n    -------\n    None\n    "
    decorated = _decorate(toy, Grown)
    params = inspect.signature(decorated).parameters
    assert params["sizes"].default == ()  # the factory's value, not a required keyword
    section = _section(decorated.__doc__ or "")
    assert "    label : str, required" in section
    assert "    sizes : tuple[int, ...], default ()" in section
    assert not any("MISSING" in line for line in section)
    # The wrap falls where the words allow, never inside "multi-level" or "split-free".
    text = " ".join(line.strip() for line in section)
    assert "multi-level" in text and "split-free" in text
    assert not any(line.rstrip().endswith("-") for line in section[2:])


def test_toy_section_leaves_out_what_the_function_documents() -> None:
    def toy(texture: object, count: int = 9, **overrides: Any) -> None:
        del texture, count, overrides

    toy.__doc__ = TOY_DOC
    doc = _decorate(toy).__doc__ or ""
    assert PLACEHOLDER not in doc
    section = _section(doc)
    assert section[2].endswith(":class:`~quilting.Toy`, replacing the one in ``options``:")
    assert section[4:] == [
        "    width : int, default 3",
        "        How wide the toy is, in whole bricks.",
        "    colour : {'red', 'blue'} or None, default None",
        "        Its paint.",
        "    ratio : float, default 0.5",
    ]
    assert doc.count("\n    count : ") == 1  # the function's own entry only
    # What surrounds the placeholder is kept as it was.
    before, after = TOY_DOC.split("    " + PLACEHOLDER)
    assert doc.startswith(before) and doc.endswith(after)


def test_toy_docstring_without_the_placeholder_is_left_alone() -> None:
    def plain(**overrides: Any) -> None:
        """Nothing to fill in here."""

    def bare(**overrides: Any) -> None:
        del overrides

    assert _decorate(plain).__doc__ == "Nothing to fill in here."
    assert _decorate(bare).__doc__ is None
    # The signature is made all the same.
    for func in (plain, bare):
        assert "width" in inspect.signature(func).parameters
