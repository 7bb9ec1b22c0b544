"""Deprecated (issue 11): `jaxhoist.physics.X` is the private `jaxhoist._physics.X` now."""

from .._deprecated import alias_moved_package

alias_moved_package(__name__, "jaxhoist._physics")
