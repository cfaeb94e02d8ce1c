"""GLSL 4.30 compute shaders of the ``gl`` cost backend, loaded by ``quilting.costs.gl``.

Installed as the package ``quilting.shaders`` (see pyproject.toml), read through
importlib.resources; constants are injected as ``#define`` lines after ``#version``.
"""
