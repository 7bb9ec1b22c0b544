"""`python -m jaxhoist ...`: the same as the `jaxhoist` command."""

from jaxhoist._apps.cli.app import entry_point

entry_point()
