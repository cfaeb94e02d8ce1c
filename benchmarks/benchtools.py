"""Shared by the benchmark scripts: tables, a description of the machine, a free port."""

from __future__ import annotations

import os
import platform
import socket
import subprocess
from pathlib import Path


def free_port() -> int:
    """A TCP port free on the loopback interface right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


def table(headers: list[str], rows: list[list[str]], left: int = 1) -> str:
    """Plain-text table: the first ``left`` columns left-aligned, the rest right-aligned."""
    widths = [max(len(row[k]) for row in [headers, *rows]) for k in range(len(headers))]

    def line(row: list[str]) -> str:
        cells = zip(row, widths, strict=True)
        return "  ".join(c.ljust(w) if k < left else c.rjust(w) for k, (c, w) in enumerate(cells))

    rule = "  ".join("-" * w for w in widths)
    return "\n".join([line(headers), rule, *(line(row) for row in rows)])


def markdown(headers: list[str], rows: list[list[str]], left: int = 1) -> str:
    """A markdown table padded to line up as plain text.

    Parameters
    ----------
    headers : list[str]
        Column titles.
    rows : list[list[str]]
        The cells.
    left : int
        The first ``left`` columns are left-aligned, the rest right-aligned.

    Returns
    -------
    str
        The table (:func:`table` with pipes).
    """
    widths = [max(len(row[k]) for row in [headers, *rows]) for k in range(len(headers))]

    def line(row: list[str]) -> str:
        cells = zip(row, widths, strict=True)
        padded = [c.ljust(w) if k < left else c.rjust(w) for k, (c, w) in enumerate(cells)]
        return "| " + " | ".join(padded) + " |"

    rule = ["-" * (w + 2) if k < left else "-" * (w + 1) + ":" for k, w in enumerate(widths)]
    return "\n".join([line(headers), "|" + "|".join(rule) + "|", *(line(row) for row in rows)])


def machine(**versions: str) -> dict[str, object]:
    """Cores, platform, Python, the given library versions and the load average now."""
    return {
        "cpu_count": os.cpu_count(),
        "platform": platform.platform(),
        "python": platform.python_version(),
        **versions,
        "loadavg": [round(x, 2) for x in os.getloadavg()],
    }


def source_tree(root: Path) -> str:
    """The commit of the checkout at ``root`` measured, and whether the engine's sources
    (``server/``) differ from it."""

    def git(*args: str) -> str:
        done = subprocess.run(["git", *args], cwd=root, capture_output=True, text=True)
        return done.stdout.strip() if done.returncode == 0 else ""

    commit = git("rev-parse", "--short", "HEAD")
    if not commit:
        return "unknown (not a git checkout)"
    changed = git("status", "--porcelain", "--", "server")
    return commit + (" + uncommitted changes in server/" if changed else "")
