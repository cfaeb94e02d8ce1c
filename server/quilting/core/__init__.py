"""The quilting algorithm: numpy, scipy and the standard library only.

Nothing here imports from the rest of the package; ``quilting.costs`` implements the cost-field
interface declared in :mod:`quilting.core.fields`.
"""
