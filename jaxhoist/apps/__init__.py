"""Deprecated (issue 11): `jaxhoist.apps.X` is the private `jaxhoist._apps.X` now."""

from .._deprecated import alias_moved_package

alias_moved_package(__name__, "jaxhoist._apps")
