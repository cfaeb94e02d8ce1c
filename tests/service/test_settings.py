"""Service settings: environment parsing, validation, and serve refusing bad values."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from quilting import InvalidParameterError
from quilting.service.settings import Settings, describe


def test_defaults_and_environment_and_flags() -> None:
    env = {
        "QUILTING_PORT": "9001",
        "QUILTING_RESULTS_TTL_S": "12.5",
        "QUILTING_API_KEYS": "k1, k2 ,",
        "QUILTING_CORS_ORIGINS": "https://a.example",
        "UNRELATED": "x",
    }
    settings = Settings.from_env(env, port=9002, workers=None)
    assert settings.port == 9002  # flags win over the environment
    assert settings.results_ttl_s == 12.5
    assert settings.api_keys == ("k1", "k2")
    assert settings.cors_origins == ("https://a.example",)
    assert settings.max_queued == 64 and settings.host == "127.0.0.1"
    assert settings.compute_workers == (os.cpu_count() or 1)


@pytest.mark.parametrize(
    "env,name",
    [
        ({"QUILTING_PORT": "eighty"}, "QUILTING_PORT"),
        ({"QUILTING_PORT": "70000"}, "port"),
        ({"QUILTING_MAX_QUEUED": "0"}, "max_queued"),
        ({"QUILTING_JOB_TIMEOUT_S": "-1"}, "job_timeout_s"),
        ({"QUILTING_DEFAULT_WAIT_S": "90"}, "max_wait_s"),
        ({"QUILTING_WEB_PAGE": "maybe"}, "QUILTING_WEB_PAGE"),
    ],
)
def test_invalid_settings_name_the_variable(env, name) -> None:
    with pytest.raises(InvalidParameterError) as info:
        Settings.from_env(env)
    assert info.value.parameter == name


@pytest.mark.parametrize(
    "word,value", [("true", True), ("ON", True), ("1", True), ("false", False), ("no", False)]
)
def test_switches_read_the_usual_words(word: str, value: bool) -> None:
    assert Settings.from_env({"QUILTING_WEB_PAGE": word}).web_page is value


@pytest.mark.parametrize(
    "values,name,allowed",
    [
        ({"port": -1}, "port", "0..65535"),
        ({"max_queued": 0}, "max_queued", ">= 1"),
        ({"port": "x"}, "port", "an integer"),
        ({"worker_mode": "fork"}, "worker_mode", "one of process, thread"),
        ({"bogus": 1}, "bogus", "a setting: host, port"),
    ],
)
def test_keywords_are_checked_like_the_environment(
    values: dict[str, object], name: str, allowed: str
) -> None:
    with pytest.raises(InvalidParameterError) as info:
        Settings(**values)
    assert info.value.parameter == name and info.value.allowed.startswith(allowed)


def test_keywords_alone_never_read_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("QUILTING_PORT", "9001")
    assert Settings().port == 8000 and Settings(host="::").port == 8000
    assert Settings.from_env().port == 9001


def test_a_bad_queue_url_is_refused_without_its_password() -> None:
    with pytest.raises(InvalidParameterError) as info:
        Settings.from_env({"QUILTING_QUEUE": "http://user:secret@host:6379/0"})
    assert info.value.parameter == "queue" and "secret" not in str(info.value)


def test_lists_are_comma_separated_and_settings_frozen() -> None:
    settings = Settings.from_env({"QUILTING_CORS_ORIGINS": " https://a.example , ,https://b"})
    assert settings.cors_origins == ("https://a.example", "https://b")
    with pytest.raises(ValueError):
        settings.port = 1


def test_every_setting_has_docs_and_a_variable() -> None:
    rows = describe()
    assert len(rows) == len({r[1] for r in rows})
    assert all(r[1].startswith("QUILTING_") and r[3] for r in rows)


def test_serve_refuses_a_bad_setting_with_one_line() -> None:
    env = {**os.environ, "QUILTING_MAX_QUEUED": "lots"}
    done = subprocess.run(
        [sys.executable, "-m", "quilting", "serve", "--port", "0"],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2
    assert "QUILTING_MAX_QUEUED" in done.stderr and "Traceback" not in done.stderr
