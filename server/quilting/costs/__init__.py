"""Cost-field backends behind the one interface of :mod:`quilting.core.fields`."""

from quilting.costs.registry import available_backends, get_backend

__all__ = ["available_backends", "get_backend"]
