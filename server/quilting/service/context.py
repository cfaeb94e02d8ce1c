"""What every route of one app shares: its settings, job queue and sandbox, the limits and
budgets derived from the settings once, and the options' schema models.

:func:`quilting.service.app.create_app` builds one :class:`Service` and keeps it as
``app.state.service``; routes reach it through :func:`quilting.service.deps.service`.
"""

from __future__ import annotations

from dataclasses import dataclass

from pydantic import BaseModel

from quilting import Budget
from quilting.options import (
    AlphaOptions,
    ExtendOptions,
    FillOptions,
    MatteOptions,
    TileOptions,
    TransferOptions,
    WangOptions,
)
from quilting.service.budgets import job_budget
from quilting.service.jobs import PixelLimits
from quilting.service.jobs.queue import JobQueue, make_queue
from quilting.service.sandbox import Sandbox
from quilting.service.schemas import options_model
from quilting.service.settings import Settings


@dataclass(frozen=True)
class Models:
    """The ``options`` JSON schema of each endpoint, generated from the options dataclasses
    with the service's limits (published as components of the OpenAPI document)."""

    synthesize: type[BaseModel]
    transfer: type[BaseModel]
    tile: type[BaseModel]
    matte: type[BaseModel]
    fill: type[BaseModel]
    extend: type[BaseModel]
    wang_tiles: type[BaseModel]
    extract_alpha: type[BaseModel]

    @classmethod
    def of(cls, settings: Settings) -> Models:
        return cls(
            synthesize=options_model(settings),
            transfer=options_model(settings, TransferOptions, name="TransferOptions", sized=False),
            tile=options_model(settings, TileOptions, name="TileOptions", sized=False),
            matte=options_model(settings, MatteOptions, name="MatteOptions", sized=False),
            fill=options_model(settings, FillOptions, name="FillOptions", sized=False),
            extend=options_model(settings, ExtendOptions, name="ExtendOptions", sized=False),
            wang_tiles=options_model(settings, WangOptions, name="WangOptions", sized=False),
            extract_alpha=options_model(settings, AlphaOptions, name="AlphaOptions", sized=False),
        )


@dataclass(frozen=True)
class Service:
    """One app's shared parts.

    Attributes
    ----------
    settings : Settings
    jobs : JobQueue
        The job store and its workers (this process's, or Redis).
    sandbox : Sandbox
        The processes that do pixel work answered at once (checking uploads, tiling, seam
        overlays), under a time and memory limit, never the event loop.
    limits : PixelLimits
        The pixel limits uploads are decoded under.
    job_budget, tile_budget : Budget
        What one job, and one ``/tile``, may use (the memory budget read once, at start).
    models : Models
    """

    settings: Settings
    jobs: JobQueue
    sandbox: Sandbox
    limits: PixelLimits
    job_budget: Budget
    tile_budget: Budget
    models: Models

    @classmethod
    def build(cls, settings: Settings) -> Service:
        # Read once: the derived budget follows the memory available when the service starts.
        memory = settings.memory_budget
        return cls(
            settings=settings,
            jobs=make_queue(settings),
            sandbox=Sandbox(settings.sandbox_workers, settings.sandbox_timeout_s, memory),
            limits=PixelLimits.of(settings),
            job_budget=job_budget(memory, settings.job_timeout_s),
            tile_budget=job_budget(memory, settings.sandbox_timeout_s),
            models=Models.of(settings),
        )

    @property
    def file_cache(self) -> str:
        """``Cache-Control`` of a finished job's files: they never change under their URL (a
        job id is never reused) and are kept results_ttl_s; private, as they may belong to
        an API key."""
        return f"private, max-age={int(self.settings.results_ttl_s)}, immutable"
