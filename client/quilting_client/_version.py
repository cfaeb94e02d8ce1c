"""The version of the client distribution: one place, read by the build and the User-Agent."""

__version__ = "0.1.0"
