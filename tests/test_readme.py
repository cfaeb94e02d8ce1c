"""The README stays true: every option is documented, and CI runs the README's test command."""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path

from quilting import MatteOptions, SynthesisOptions, TransferOptions

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()


def test_every_option_is_in_the_parameter_table() -> None:
    for option in fields(SynthesisOptions):
        assert f"| `{option.name}` |" in README, option.name


def test_every_transfer_option_is_documented() -> None:
    section = README.split("## Texture transfer")[1].split("\n## ")[0]
    inherited = {f.name for f in fields(SynthesisOptions)}
    for option in fields(TransferOptions):
        if option.name not in inherited:
            assert f"| `{option.name}` |" in section, option.name
        assert f"{option.name}=" in section, option.name  # in the signature


def test_every_matte_option_is_documented() -> None:
    section = README.split("## Texture matting")[1].split("\n## ")[0]
    inherited = {f.name for f in fields(SynthesisOptions)}
    for option in fields(MatteOptions):
        if option.name not in inherited:
            assert f"| `{option.name}` |" in section, option.name
        assert f"{option.name}=" in section, option.name  # in the signature


def test_ci_runs_the_readme_test_command() -> None:
    ci = (ROOT / ".ci" / "run").read_text().strip().splitlines()[-1]
    assert ci in README


def test_readme_images_exist() -> None:
    for line in README.splitlines():
        for part in line.split("](")[1:]:
            target = part.split(")")[0]
            if target.endswith(".png"):
                assert (ROOT / target).is_file(), target


def test_every_service_setting_is_in_the_settings_table() -> None:
    from quilting.service.settings import describe

    rows = {
        line.split("|")[1].strip(): line for line in README.splitlines() if line.startswith("| `")
    }
    for _, variable, default, _ in describe():
        row = rows.get(f"`{variable}`")
        assert row is not None, variable
        shown = ",".join(default) if isinstance(default, tuple) else str(default)
        assert f"| {shown or '(none)'} |" in row, (variable, row)
