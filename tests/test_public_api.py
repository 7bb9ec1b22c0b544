"""The package's surface (issue 11): `jaxhoist`, `jaxhoist.plots` and `jaxhoist.observables` are public, every
other module is private (`_`-prefixed); the layout before 0.2 still imports, with one DeprecationWarning, and
names the very same objects; the layers import one way (physics, io <- numerics <- apps)."""

import ast
import importlib
import sys
from pathlib import Path

import pytest

import jaxhoist as jh

PACKAGE = Path(jh.__file__).parent
OLD_LAYOUT = ("physics", "numerics", "apps", "io")


def test_only_public_modules_lack_the_underscore():
    public = {p.name for p in PACKAGE.iterdir() if not p.name.startswith(("_", ".")) and p.name != "py.typed"}
    assert public == {"plots.py", "observables.py", *OLD_LAYOUT}


def _forget(old: str) -> None:
    """Drop the shim `jaxhoist.<old>` from the import cache, so that importing it again warns again."""
    for name in [m for m in sys.modules if m == f"jaxhoist.{old}" or m.startswith(f"jaxhoist.{old}.")]:
        del sys.modules[name]


@pytest.mark.parametrize("old", OLD_LAYOUT)
def test_old_layout_warns_and_aliases(old):
    _forget(old)
    moved = f"jaxhoist.{old} moved to the private package jaxhoist._{old}"
    with pytest.warns(DeprecationWarning, match=moved):
        shim = importlib.import_module(f"jaxhoist.{old}")
    private = importlib.import_module(f"jaxhoist._{old}")
    for info in __import__("pkgutil").iter_modules(private.__path__):
        assert sys.modules[f"jaxhoist.{old}.{info.name}"] is sys.modules[f"jaxhoist._{old}.{info.name}"]
        assert getattr(shim, info.name) is sys.modules[f"jaxhoist._{old}.{info.name}"]


def test_old_import_statements_give_the_public_objects():
    for old in OLD_LAYOUT:
        _forget(old)
    with pytest.warns(DeprecationWarning):
        from jaxhoist.apps.scan import scan
        from jaxhoist.io.scenario import load_scenario
        from jaxhoist.physics.params import Load
    assert (scan, load_scenario, Load) == (jh.scan, jh.load_scenario, jh.Load)


def _imports(path: Path) -> set[str]:
    """The jaxhoist layers (`_physics`, ...) that the module at `path` imports at any depth."""
    layers = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            mod = node.module or ""
            if node.level == 2 or (node.level == 0 and mod.startswith("jaxhoist.")):
                layers.add(mod.removeprefix("jaxhoist.").split(".")[0])
    return layers


def test_layers_import_one_way():
    allowed = {"_physics": {"_physics"}, "_io": {"_physics", "_io"}}
    allowed["_numerics"] = allowed["_io"] | {"_numerics"}
    allowed["_apps"] = allowed["_numerics"] | {"_apps"}
    for layer, ok in allowed.items():
        for path in (PACKAGE / layer).glob("*.py"):
            bad = _imports(path) - ok - {""}
            assert not bad & set(allowed), f"{path.relative_to(PACKAGE)} imports {bad & set(allowed)}"
