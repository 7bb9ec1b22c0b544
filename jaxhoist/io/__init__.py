"""Deprecated (issue 11): `jaxhoist.io.X` is the private `jaxhoist._io.X` now."""

from .._deprecated import alias_moved_package

alias_moved_package(__name__, "jaxhoist._io")
