"""Dotted parameter paths: moved to `jaxhoist._physics.paths` (issue 11: one implementation for scan,
identify, `--set` and scenario overrides); these names stay importable from here."""

from .._physics.paths import check_path as check_path
from .._physics.paths import get_param as get_param
from .._physics.paths import leaf_getter as _getter  # noqa: F401  (the earlier private name)
from .._physics.paths import param_unit as param_unit
from .._physics.paths import parse_path as parse_path
from .._physics.paths import set_param as set_param
