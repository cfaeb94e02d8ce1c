"""Rewrite the generated parts of README.md and docs/*.md from the code.

    .venv/bin/python docs/generate.py           rewrite every generated region in place
    .venv/bin/python docs/generate.py --check   change nothing; exit 1 naming each file whose
                                                regions differ from what the code gives

The tables of parameters and settings, the signatures and the command-line synopses are not
written by hand: each sits in a region of a Markdown file,

    <!-- generated:KIND ARGUMENT... -->
    (the generated text)
    <!-- end generated -->

and this script replaces what is between the two markers. The kinds:

- ``options CLASS [beyond OTHER]``: a table of the fields of ``quilting.CLASS`` (an options
  dataclass): name, default, allowed values (from the field metadata ``ge``, ``le``,
  ``choices``, ``kind``) and ``metadata["doc"]``. With ``beyond OTHER``, only the fields that
  ``OTHER`` lacks or declares differently (another default or doc).
- ``signature DOTTED.NAME``: the call signature of a function or method, from
  ``inspect.signature``, as a ``text`` block.
- ``settings``: the service settings from ``quilting.service.settings.describe()``, with the
  ``quilting serve`` flag of each where there is one.
- ``usage``: the usage lines of every ``quilting`` subcommand and of ``quilting-remote``.
- ``modules FOLDER [only]``: a table of the Python modules under ``FOLDER`` (relative to the
  repository; with ``only``, not its subfolders), each with the first paragraph of its
  docstring: the code map of ``docs/architecture.md``, in step with the modules as they are.

Besides the Markdown, it writes ``client/quilting_client/options.json``: the options each
endpoint takes, as the service's ``/openapi.json`` publishes them (names, types, choices,
descriptions; no defaults or limits, which are a deployment's), from which the remote client
makes its command-line flags without importing the engine.

Text around the regions is the docs' own and is never touched. ``tests/test_docs.py`` fails when
a committed file differs from what this script writes, so after changing an option's metadata,
a setting or a command-line flag, run this script and commit the Markdown files with the code.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import importlib
import inspect
import os
import re
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]


def markdown_files() -> list[Path]:
    """README.md and every ``docs/*.md``, in a stable order."""
    return [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


REGION = re.compile(
    r"(?P<start><!-- generated:(?P<spec>[^>]*?) -->\n)(?P<body>.*?)(?P<end><!-- end generated -->)",
    re.DOTALL,
)

#: Width of the signatures and usage lines.
WIDTH = 96
MiB = 1 << 20
GiB = 1 << 30


# --- values -----------------------------------------------------------------------------------


def shown(value: Any) -> str:
    """A default or a choice as code: Python's spelling (``None``, ``'auto'``, ``()``)."""
    return repr(value)


def cell(text: str) -> str:
    """Text that is safe inside a Markdown table cell."""
    return " ".join(text.split()).replace("|", "\\|")


def number(value: Any) -> str:
    """A limit as text: ``2^64 - 1`` for the largest seed, ``1e+06`` for large floats."""
    if isinstance(value, float) and value >= 1e5:
        return f"{value:g}"
    if isinstance(value, int) and value >= 1 << 32:
        exponent = value.bit_length() - 1
        if value == (1 << (exponent + 1)) - 1:
            return f"2^{exponent + 1} - 1"
    return str(value)


def allowed(metadata: Any, name: str) -> str:
    """The allowed values of an option field, from its metadata."""
    choices = metadata.get("choices")
    if choices is not None:
        return ", ".join(f"`{shown(c)}`" for c in choices)
    kind = metadata.get("kind")
    if kind == "color_ranges":
        return "list of `(low, high)` colours"
    if kind == "direction":
        return "`None` or `(x, y, z)`, z > 0"
    if kind == "transforms":
        from quilting.core.sources import PRESETS, TRANSFORMS

        return (
            ", ".join(f"`{p}`" for p in PRESETS)
            + " or a list of "
            + ", ".join(f"`{t}`" for t in TRANSFORMS)
        )
    if kind == "weights":
        return "`None` or a list of numbers > 0, one per example"
    if kind == "bool":
        return "`True`, `False`"
    if name == "backend":
        from quilting.backends import BACKEND_NAMES

        return ", ".join(f"`{shown(b)}`" for b in BACKEND_NAMES)
    lo, hi = metadata.get("ge"), metadata.get("le")
    if lo is None:
        return "text"
    text = f"{number(lo)} .. {number(hi)}" if hi is not None else f"≥ {number(lo)}"
    step = metadata.get("multiple_of")
    if step is not None:
        text += ", even" if step == 2 else f", a multiple of {step}"
    if metadata.get("optional"):
        text += ", or `None`"
    return text


# --- the kinds ----------------------------------------------------------------------------------


def options_table(class_name: str, beyond: str | None = None) -> str:
    import quilting

    cls = getattr(quilting, class_name)
    skip: dict[str, Any] = {}
    if beyond is not None:
        skip = {f.name: f for f in dataclasses.fields(getattr(quilting, beyond))}
    rows = ["| parameter | default | allowed | what it does |", "|---|---|---|---|"]
    for f in dataclasses.fields(cls):
        other = skip.get(f.name)
        if other is not None and other.default == f.default and other.metadata == f.metadata:
            continue
        doc = cell(str(f.metadata["doc"]))
        rows.append(
            f"| `{f.name}` | `{shown(f.default)}` | {allowed(f.metadata, f.name)} | {doc} |"
        )
    return "\n".join(rows) + "\n"


def resolve(dotted: str) -> Any:
    """The object a dotted name names: the longest importable module prefix, then attributes."""
    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        try:
            target: Any = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        for attribute in parts[i:]:
            target = getattr(target, attribute)
        return target
    raise ImportError(dotted)


def signature(dotted: str) -> str:
    target = resolve(dotted)
    sig = inspect.signature(target)
    parameters = list(sig.parameters.values())
    if parameters and parameters[0].name == "self":
        parameters = parameters[1:]
    words: list[str] = []
    star_done = False
    for p in parameters:
        if p.kind is p.KEYWORD_ONLY and not star_done:
            words.append("*")
            star_done = True
        if p.kind is p.VAR_POSITIONAL:
            star_done = True
            words.append(f"*{p.name}")
        elif p.kind is p.VAR_KEYWORD:
            words.append(f"**{p.name}")
        elif p.default is p.empty:
            words.append(p.name)
        else:
            words.append(f"{p.name}={shown(p.default)}")
    returns = sig.return_annotation
    if returns is sig.empty:
        tail = ""
    else:
        tail = " -> " + (returns if isinstance(returns, str) else getattr(returns, "__name__", ""))
    name = dotted
    lines: list[str] = []
    line = f"{name}("
    indent = "    "
    for i, word in enumerate(words):
        piece = word + (", " if i < len(words) - 1 else "")
        if len(line) + len(piece.rstrip()) > WIDTH:
            lines.append(line.rstrip())
            line = indent
        line += piece
    line += ")" + tail
    lines.append(line)
    return "```text\n" + "\n".join(lines) + "\n```\n"


def settings_table() -> str:
    from quilting.cli import build_parser
    from quilting.service.settings import describe

    flags = {}
    serve = _subcommands(build_parser())["serve"]
    for action in serve._actions:
        if action.option_strings and action.dest != "help":
            flags[action.dest] = action.option_strings[-1]
    rows = ["| variable | `quilting serve` flag | default | what it does |", "|---|---|---|---|"]
    for name, variable, default, doc in describe():
        if isinstance(default, tuple):
            text = ",".join(default) or "(none)"
        elif isinstance(default, bool):
            text = str(default).lower()
        elif (
            isinstance(default, int) and name.endswith("_bytes") and default and default % MiB == 0
        ):  # a size (0 is "derived", not a size)
            size = f"{default // GiB} GiB" if default % GiB == 0 else f"{default // MiB} MiB"
            text = f"{default} ({size})"
        else:
            text = str(default)
        flag = f"`{flags[name]}`" if name in flags else ""
        rows.append(f"| `{variable}` | {flag} | {text} | {cell(doc)} |")
    return "\n".join(rows) + "\n"


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def usage() -> str:
    from quilting.cli import build_parser
    from quilting_client.cli import build_parser as remote_parser

    saved = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = str(WIDTH + 2)  # argparse wraps at the terminal's width - 2
    try:
        texts = []
        for sub in _subcommands(build_parser()).values():
            texts.append(sub.format_usage())
        for remote in _subcommands(remote_parser()).values():
            texts.append(remote.format_usage())
    finally:
        if saved is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = saved
    lines = []
    for text in texts:
        first, *rest = text.rstrip("\n").split("\n")
        lines.append(first.removeprefix("usage: "))
        lines += [line.removeprefix(" " * len("usage: ")) for line in rest]
    return "```text\n" + "\n".join(lines) + "\n```\n"


def modules_table(folder: str, only: str = "") -> str:
    """The modules under ``folder`` (with ``only``: in it, not in its subfolders), ``__init__``
    first in each package, each with the first paragraph of its docstring, as a table."""
    base = ROOT / folder
    rows = ["| module | its role |", "|---|---|"]
    found = base.glob("*.py") if only == "only" else base.rglob("*.py")
    paths = sorted(found, key=lambda p: (p.parent.parts, p.name != "__init__.py", p.name))
    for path in paths:
        doc = ast.get_docstring(ast.parse(path.read_text("utf-8"))) or ""
        role = doc.split("\n\n")[0]  # the docstring's first paragraph
        rows.append(f"| `{path.relative_to(ROOT)}` | {cell(role)} |")
    return "\n".join(rows) + "\n"


KINDS: dict[str, Callable[..., str]] = {
    "options": lambda cls, *rest: options_table(cls, rest[1] if rest[:1] == ("beyond",) else None),
    "signature": signature,
    "settings": settings_table,
    "usage": usage,
    "modules": modules_table,
}


# --- files --------------------------------------------------------------------------------------


def regions(text: str) -> Iterator[re.Match[str]]:
    return REGION.finditer(text)


def render(spec: str) -> str:
    kind, *arguments = spec.split()
    if kind not in KINDS:
        raise ValueError(f"unknown generated region kind {kind!r} (known: {', '.join(KINDS)})")
    return KINDS[kind](*arguments)


def rewrite(text: str) -> str:
    """``text`` with every generated region's body replaced by what the code gives now."""
    return REGION.sub(
        lambda m: m["start"] + render(m["spec"].strip()) + m["end"],
        text,
    )


#: The client's copy of the service's options schemas.
CLIENT_OPTIONS = ROOT / "client" / "quilting_client" / "options.json"
#: The component of each operation's options in the OpenAPI document.
OPERATIONS = {
    "synthesize": "SynthesizeOptions",
    "transfer": "TransferOptions",
    "matte": "MatteOptions",
    "tile": "TileOptions",
    "fill": "FillOptions",
    "extend": "ExtendOptions",
    "wang_tiles": "WangOptions",
    "extract_alpha": "AlphaOptions",
}


def client_options() -> str:
    """``options.json`` of the client: per operation, each option's schema without its
    default, limits or title."""
    import json

    from quilting.service.app import create_app
    from quilting.service.settings import Settings

    schemas = create_app(Settings()).openapi()["components"]["schemas"]
    kept = ("type", "enum", "items", "anyOf", "description")

    def trim(schema: dict[str, object]) -> dict[str, object]:
        out: dict[str, object] = {}
        for key, value in schema.items():
            if key not in kept:
                continue
            if key == "items" and isinstance(value, dict):
                value = trim(value)
            if key == "anyOf" and isinstance(value, list):
                value = [trim(v) for v in value]
            out[key] = value
        return out

    document = {
        operation: {name: trim(prop) for name, prop in schemas[component]["properties"].items()}
        for operation, component in OPERATIONS.items()
    }
    return json.dumps(document, indent=1) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--check", action="store_true", help="exit 1 if a file differs; change nothing"
    )
    args = parser.parse_args(argv)
    stale = []
    made = [(path, rewrite) for path in markdown_files()]
    made.append((CLIENT_OPTIONS, lambda _: client_options()))
    for path, write in made:
        text = path.read_text() if path.exists() else ""
        new = write(text)
        if new == text:
            continue
        stale.append(path)
        if not args.check:
            path.write_text(new)
    for path in stale:
        verb = "differs from the code" if args.check else "rewritten"
        print(f"{path.relative_to(ROOT)}: {verb}", file=sys.stderr)
    if args.check and stale:
        print("run: .venv/bin/python docs/generate.py", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
