"""Deprecated (issue 11): `jaxhoist.numerics.X` is the private `jaxhoist._numerics.X` now."""

from .._deprecated import alias_moved_package

alias_moved_package(__name__, "jaxhoist._numerics")
