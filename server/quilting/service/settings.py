"""Service settings: typed, validated, from ``QUILTING_*`` environment variables and flags.

Every limit the service enforces is a field of :class:`Settings`, declared once: its default,
its description and its limits (``ge``/``le``, or the choices of a ``Literal``). The docs'
settings table is generated from these fields (:func:`describe`) and checked by the tests.

``Settings(...)`` takes keywords and nothing else: it never reads the environment, so the
defaults are the defaults wherever it runs (tests, ``docs/generate.py``).
:meth:`Settings.from_env` reads ``QUILTING_<NAME>`` variables through pydantic-settings'
environment source, with the flags on top. Every value refused is an
:class:`~quilting.InvalidParameterError` (the CLI prints it in one line), never a pydantic
``ValidationError``: it names the setting, or the variable when its text is not even of the
setting's type (``QUILTING_PORT='eighty'``).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from contextvars import ContextVar
from typing import Annotated, Any, Literal, get_args, get_origin

from pydantic import (
    BeforeValidator,
    Field,
    TypeAdapter,
    ValidationError,
    field_validator,
    model_validator,
)
from pydantic.fields import FieldInfo
from pydantic_settings import (
    BaseSettings,
    EnvSettingsSource,
    PydanticBaseSettingsSource,
    SettingsConfigDict,
)

from quilting import InvalidParameterError

MiB = 1 << 20
GiB = 1 << 30

#: The most and the least a job's memory budget is when job_memory_bytes is 0 (derived): a
#: budget below the floor would refuse every job.
DEFAULT_MEMORY_BUDGET = 2 * GiB
MIN_MEMORY_BUDGET = 64 * MiB

#: URL schemes of a Redis server that ``queue`` accepts.
QUEUE_SCHEMES = ("redis://", "rediss://", "unix://")

#: Prefix of the settings' environment variables.
ENV_PREFIX = "QUILTING_"

#: The words a switch may be spelled with. pydantic's own bool also takes t/f/y/n: a typo
#: there would silently pick a side, so the environment keeps the words it always took.
_TRUE = ("1", "true", "yes", "on")
_FALSE = ("0", "false", "no", "off")

#: pydantic error types that mean "parsed, but outside the setting's limits" (named by the
#: setting); every other error means the text is not of the setting's type (named by the
#: variable when it came from the environment).
_LIMIT_ERRORS = ("greater_than_equal", "less_than_equal", "literal_error")

#: The environment :meth:`Settings.from_env` reads while it builds one; None (the default) for
#: ``Settings(...)``, which reads keywords only.
_ENVIRON: ContextVar[Mapping[str, str] | None] = ContextVar("quilting_environ", default=None)


def _switch(value: Any) -> Any:
    """A switch's text as a bool; anything else to pydantic's bool (True, 0...)."""
    if not isinstance(value, str):
        return value
    word = value.strip().lower()
    if word in _TRUE:
        return True
    if word in _FALSE:
        return False
    raise ValueError(f"not one of {', '.join(_TRUE + _FALSE)}")


Switch = Annotated[bool, BeforeValidator(_switch)]


class _Environment(EnvSettingsSource):
    """pydantic-settings' environment source over a given mapping instead of ``os.environ``.

    Values are stripped; a list setting (``api_keys``, ``cors_origins``) is comma-separated
    text, blanks dropped, where pydantic-settings would expect JSON.
    """

    def __init__(self, settings_cls: type[BaseSettings], environ: Mapping[str, str]) -> None:
        # The prefix passed, not left to the config: older pydantic-settings only read it there
        # for the sources they build themselves.
        super().__init__(settings_cls, case_sensitive=False, env_prefix=ENV_PREFIX)
        # Keys as the source looks them up (lower case: the config is case-insensitive).
        self.env_vars = {key.lower(): value.strip() for key, value in environ.items()}

    def prepare_field_value(
        self, field_name: str, field: FieldInfo, value: Any, value_is_complex: bool
    ) -> Any:
        if isinstance(value, str) and get_origin(field.annotation) is tuple:
            return tuple(part.strip() for part in value.split(",") if part.strip())
        return super().prepare_field_value(field_name, field, value, value_is_complex)


class Settings(BaseSettings):
    """Everything the service can be configured with (env ``QUILTING_<NAME>``).

    Built from keywords (``Settings(port=9000)``, the rest at their defaults) or from the
    environment (:meth:`from_env`). Frozen; an unknown keyword or a value outside a setting's
    limits raises :class:`~quilting.InvalidParameterError`.
    """

    model_config = SettingsConfigDict(env_prefix=ENV_PREFIX, frozen=True, extra="forbid")

    host: str = Field("127.0.0.1", description="Address to listen on.")
    port: int = Field(8000, description="TCP port.", ge=0, le=65535)
    workers: int = Field(
        0, description="Compute workers (jobs run at once); 0 = one per CPU core.", ge=0, le=256
    )
    worker_mode: Literal["process", "thread"] = Field(
        "process",
        description="process: each worker is a process (uses every core); thread: threads in "
        "the service process (lighter, but the engine holds the GIL: about one core in all).",
    )
    backend: str = Field(
        "auto",
        description="Default cost backend of jobs: auto (gl on a hardware GPU, else fft), fft, "
        "gl or reference.",
    )
    max_queued: int = Field(
        64, description="Jobs waiting for a worker before 503 queue_full.", ge=1
    )
    results_max_count: int = Field(256, description="Finished jobs whose results are kept.", ge=1)
    results_max_bytes: int = Field(1024 * MiB, description="Total bytes of kept results.", ge=1)
    results_ttl_s: float = Field(3600.0, description="Seconds a result is kept (then 410).", ge=1.0)
    job_timeout_s: float = Field(
        300.0, description="A job running longer fails with job_timeout.", ge=0.1
    )
    job_memory_bytes: int = Field(
        0,
        description="Memory a job may use beyond what its worker process holds once started "
        "(bytes); 0 = min(2 GiB, available memory / (workers + 1)) when the service starts. A "
        "job past it fails with job_too_large (worker_mode=process: the worker's data segment "
        "is capped, RLIMIT_DATA; thread workers share the service process and are not "
        "limited). Also the budget of each sandbox call (422 image_too_costly past it).",
        ge=0,
    )
    sandbox_workers: int = Field(
        1,
        description="Processes that check uploads' pixels, make /tile images and draw seam "
        "overlays, each under job_memory_bytes and sandbox_timeout_s (the API process decodes "
        "nothing).",
        ge=1,
        le=64,
    )
    sandbox_timeout_s: float = Field(
        20.0,
        description="Seconds one sandbox call (checking a submission's images, a /tile, a seam "
        "overlay) may take: past it the process is killed and replaced and the request gets "
        "422 image_too_costly; also the longest a request waits for a free sandbox process "
        "(503 sandbox_busy).",
        ge=0.1,
    )
    max_body_bytes: int = Field(
        64 * MiB, description="Largest request body (413 body_too_large).", ge=1
    )
    max_file_bytes: int = Field(
        32 * MiB, description="Largest uploaded file (413 file_too_large).", ge=1
    )
    max_input_pixels: int = Field(
        25_000_000,
        description="Most pixels an uploaded image may declare (422 image_too_large).",
        ge=1,
    )
    max_output_pixels: int = Field(
        67_108_864,
        description="Most output pixels, width x height (422 invalid_parameter).",
        ge=1,
    )
    max_side: int = Field(16384, description="Longest output side in pixels.", ge=1, le=65536)
    max_companions: int = Field(8, description="Companion maps per job.", ge=0, le=64)
    max_layers: int = Field(8, description="Texture layers per matte job.", ge=1, le=64)
    max_textures: int = Field(
        8,
        description="Example textures per synthesis or Wang tile job (the texture part "
        "repeated; 422 too_many_textures).",
        ge=1,
        le=64,
    )
    default_wait_s: float = Field(10.0, description="Default of the wait query parameter.", ge=0.0)
    max_wait_s: float = Field(60.0, description="Largest accepted wait.", ge=0.0)
    drain_grace_s: float = Field(
        30.0, description="On SIGTERM, how long running jobs may finish.", ge=0.0
    )
    api_keys: tuple[str, ...] = Field(
        (),
        description="Comma-separated API keys; when set, every job endpoint needs one (401).",
    )
    metrics_public: Switch = Field(
        False,
        description="Serve /metrics without an API key even when QUILTING_API_KEYS is set (a "
        "scraper without a key); false: /metrics needs a key like the job endpoints.",
    )
    request_timeout_s: float = Field(
        30.0,
        description="Seconds a client has to send its whole request body; a slower one is "
        "dropped (408 request_timeout).",
        ge=0.1,
    )
    cors_origins: tuple[str, ...] = Field(
        (), description="Comma-separated origins allowed by CORS."
    )
    web_page: Switch = Field(
        True, description="Serve the browser page at / (false: the HTTP API alone)."
    )
    queue: str = Field(
        "memory",
        description="Where jobs live: memory (this process computes them) or a Redis URL "
        "(redis://host:6379/0): jobs, progress and results in Redis, computed by "
        "`quilting worker` processes; any API replica answers for any job.",
    )
    heartbeat_timeout_s: float = Field(
        60.0,
        description="Distributed queue: a worker silent this long is taken for dead and its "
        "job is run again by another worker.",
        ge=1.0,
    )
    redis_timeout_s: float = Field(
        2.0,
        description="Distributed queue: seconds to connect to Redis, and to wait for each "
        "answer, before a request gets 503 queue_unavailable.",
        ge=0.1,
    )
    max_retries: int = Field(
        3,
        description="Distributed queue: how many times a job is run again after its worker "
        "died, before it fails with job_abandoned.",
        ge=0,
        le=100,
    )

    def __init__(self, **values: Any) -> None:
        try:
            super().__init__(**values)
        except ValidationError as exc:
            # The message, not pydantic's report: the CLI prints it as the one line it says.
            raise _refusal(exc, values, _ENVIRON.get()) from None

    @classmethod
    def settings_customise_sources(
        cls,
        settings_cls: type[BaseSettings],
        init_settings: PydanticBaseSettingsSource,
        env_settings: PydanticBaseSettingsSource,
        dotenv_settings: PydanticBaseSettingsSource,
        file_secret_settings: PydanticBaseSettingsSource,
    ) -> tuple[PydanticBaseSettingsSource, ...]:
        """Keywords first, then the environment :meth:`from_env` was given (no .env file, no
        secrets directory, and no environment at all for ``Settings(...)``)."""
        environ = _ENVIRON.get()
        if environ is None:
            return (init_settings,)
        return (init_settings, _Environment(settings_cls, environ))

    @field_validator("queue")
    @classmethod
    def _check_queue(cls, queue: str) -> str:
        if queue != "memory" and not queue.startswith(QUEUE_SCHEMES):
            scheme = queue.partition("://")[0]  # never echo a password in the URL
            raise InvalidParameterError(
                "queue", f"{scheme}://...", "memory or a Redis URL (redis://, rediss://, unix://)"
            )
        return queue

    @field_validator("api_keys")
    @classmethod
    def _check_api_keys(cls, keys: tuple[str, ...]) -> tuple[str, ...]:
        if any(not key or "," in key for key in keys):
            # Never echo a key.
            raise InvalidParameterError("api_keys", "...", "non-empty keys without commas")
        return keys

    @model_validator(mode="after")
    def _check_waits(self) -> Settings:
        if self.max_wait_s < self.default_wait_s:
            raise InvalidParameterError(
                "max_wait_s", self.max_wait_s, f">= default_wait_s ({self.default_wait_s})"
            )
        return self

    @property
    def compute_workers(self) -> int:
        """Worker threads actually started."""
        return self.workers or (os.cpu_count() or 1)

    @property
    def memory_budget(self) -> int:
        """The memory budget of a job and of a sandbox call in bytes: ``job_memory_bytes``,
        or when that is 0, min(2 GiB, available memory / (workers + 1)) (the API process and
        every worker get a share; read from ``/proc/meminfo`` when asked, 2 GiB where it
        cannot be read), and at least 64 MiB."""
        if self.job_memory_bytes:
            return self.job_memory_bytes
        available = available_memory()
        if available is None:
            return DEFAULT_MEMORY_BUDGET
        share = available // (self.compute_workers + 1)
        return max(MIN_MEMORY_BUDGET, min(DEFAULT_MEMORY_BUDGET, share))

    @classmethod
    def from_env(cls, environ: Mapping[str, str] | None = None, **overrides: Any) -> Settings:
        """Settings from ``QUILTING_*`` variables, then ``overrides`` (flags) on top.

        Parameters
        ----------
        environ : Mapping[str, str], optional
            The variables (default: ``os.environ``); other names than ``QUILTING_<setting>``
            are ignored. Switches take 1/true/yes/on and 0/false/no/off, lists are
            comma-separated.
        **overrides
            Settings by name; a None is "not given" (a flag left out) and leaves the
            variable's value or the default.

        Raises
        ------
        InvalidParameterError
            A value that does not parse, named by its variable (``QUILTING_PORT``), or one
            outside its limits, named by its setting (``port``).
        """
        given = {name: value for name, value in overrides.items() if value is not None}
        token = _ENVIRON.set(os.environ if environ is None else environ)
        try:
            return cls(**given)
        finally:
            _ENVIRON.reset(token)


def _limits(info: FieldInfo) -> tuple[Any, Any]:
    """A field's ``ge`` and ``le`` (None where it has none)."""
    lo = next((m.ge for m in info.metadata if hasattr(m, "ge")), None)
    hi = next((m.le for m in info.metadata if hasattr(m, "le")), None)
    return lo, hi


#: What a value of each setting's type must be, as the refusal says it.
_KINDS = {"int": "an integer", "float": "a number", "bool": "true or false", "str": "a string"}


def _refusal(
    error: ValidationError, given: Mapping[str, Any], environ: Mapping[str, str] | None
) -> InvalidParameterError:
    """The :class:`InvalidParameterError` of the first thing pydantic refused: a value that is
    not of its type before one outside its limits (the order in which they used to be
    checked), the checks across settings raising theirs themselves."""
    errors = sorted(error.errors(), key=lambda e: e["type"] in _LIMIT_ERRORS)
    first = errors[0]
    cause = first.get("ctx", {}).get("error")
    if isinstance(cause, InvalidParameterError):
        return cause
    fields = Settings.model_fields
    name = str(first["loc"][0]) if first["loc"] else ""
    value = first["input"]
    if name not in fields:
        return InvalidParameterError(name, value, "a setting: " + ", ".join(fields))
    info = fields[name]
    annotation: Any = info.annotation  # every setting has one
    if first["type"] == "literal_error":
        return InvalidParameterError(name, value, "one of " + ", ".join(get_args(annotation)))
    if first["type"] in _LIMIT_ERRORS:
        lo, hi = _limits(info)
        # The number, not the variable's text it was parsed from.
        value = TypeAdapter(annotation).validate_python(value)
        return InvalidParameterError(name, value, f"{lo}..{hi}" if hi is not None else f">= {lo}")
    name_of_type = getattr(annotation, "__name__", str(annotation))
    kind = _KINDS.get(name_of_type, f"a {name_of_type}")
    variable = ENV_PREFIX + name.upper()
    if environ is not None and name not in given and variable in environ:
        return InvalidParameterError(variable, value, kind)
    return InvalidParameterError(name, value, kind)


def available_memory() -> int | None:
    """Bytes of memory the kernel says are available (``MemAvailable``), or None where
    ``/proc/meminfo`` cannot be read (not Linux)."""
    try:
        with open("/proc/meminfo") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def describe() -> list[tuple[str, str, Any, str]]:
    """``(field, environment variable, default, doc)`` of every setting, for docs and tests."""
    return [
        (name, ENV_PREFIX + name.upper(), info.default, info.description or "")
        for name, info in Settings.model_fields.items()
    ]
