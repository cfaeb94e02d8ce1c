"""The service's routes, one router per resource: the submissions (synthesize, transfer,
matte, fill and extend, Wang tiles), tile, jobs, operations (health, readiness, metrics), the
browser page and the API docs. :func:`quilting.service.app.create_app` includes them in this
order, the order of the OpenAPI document's paths."""
