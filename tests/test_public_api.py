"""The package's surface (issue 11): `jaxhoist`, `jaxhoist.plots` and `jaxhoist.observables` are public, every
other module is private (`_`-prefixed); the layers import one way (physics, io <- numerics <- apps)."""

import ast
from pathlib import Path

import jaxhoist as jh

PACKAGE = Path(jh.__file__).parent


def test_only_public_modules_lack_the_underscore():
    public = {p.name for p in PACKAGE.iterdir() if not p.name.startswith(("_", ".")) and p.name != "py.typed"}
    assert public == {"plots.py", "observables.py"}


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
