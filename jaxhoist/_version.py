"""The package version: the one source is pyproject.toml, read from the installed package's metadata."""

import importlib.metadata as _metadata

try:
    __version__ = _metadata.version("jaxhoist")
except _metadata.PackageNotFoundError:  # a source tree used without installing it
    __version__ = "unknown"  # as the result files write it (io.results)
