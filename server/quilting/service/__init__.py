"""The HTTP service: FastAPI app, job store, worker threads, settings.

Only :mod:`quilting.service.app` imports FastAPI/Starlette and only :mod:`quilting.service.server`
imports uvicorn; the rest is plain Python over the engine's public API.
"""
