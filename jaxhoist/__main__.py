"""`python -m jaxhoist ...`: the same as the `jaxhoist` command."""

from jaxhoist.apps.cli import main

raise SystemExit(main())
