"""What operators and load balancers ask: liveness, readiness and Prometheus metrics."""

from __future__ import annotations

from fastapi import APIRouter, Depends, Request
from fastapi.responses import JSONResponse, PlainTextResponse

from quilting import matting_available
from quilting.service.deps import ServiceDep, metrics_reader
from quilting.service.metrics import metrics_text
from quilting.service.openapi import problems
from quilting.service.problems import Problem, queue_full

router = APIRouter()


@router.get("/healthz", operation_id="healthz", summary="Liveness")
async def healthz() -> dict[str, str]:
    return {"status": "ok"}


@router.get("/readyz", operation_id="readyz", summary="Readiness", responses=problems(503))
async def readyz(request: Request, service: ServiceDep) -> JSONResponse:
    if request.app.state.draining:
        raise Problem(503, "draining", "the service is shutting down")
    fields = await service.jobs.readiness()
    if fields["queue_depth"] >= service.settings.max_queued:
        raise queue_full(fields["queue_depth"])
    # Whether /extract-alpha (and a trimap beside a texture) can be served: a page or a
    # pipeline can leave the feature out rather than meet 503 matting_unavailable.
    return JSONResponse({"status": "ready", **fields, "matting": matting_available()})


@router.get(
    "/metrics",
    operation_id="metrics",
    summary="Prometheus metrics",
    response_class=PlainTextResponse,
    dependencies=[Depends(metrics_reader)],
    responses=problems(401, 422),
)
async def metrics(service: ServiceDep) -> PlainTextResponse:
    text = metrics_text(await service.jobs.figures())
    return PlainTextResponse(text, media_type="text/plain; version=0.0.4")
