"""The package's surface: `jaxhoist`, `jaxhoist.plots` and `jaxhoist.observables` are public, every other
module is private (`_`-prefixed); the layers import one way (physics, io <- numerics <- apps), every family
sub-package has a face, the command line imports the library and never the reverse, and the elastic core
does not import the rigid model. Every module of every sub-package is read, and every relative and absolute
import in it, at any depth (imports inside functions included)."""

import ast
import subprocess
import sys
from pathlib import Path

import jaxhoist as jh

PACKAGE = Path(jh.__file__).parent
MODULES = sorted(PACKAGE.rglob("*.py"))
#: The families: sub-packages, each with a face (`__init__.py` of imports only).
FAMILIES = (
    "_apps/scan",
    "_apps/bifurcation",
    "_apps/identify",
    "_apps/plots",
    "_apps/cli",
    "_physics/rigid",
    "_numerics/rigid",
)


def _module(path: Path) -> str:
    """The dotted name of the module at `path` (a package for its `__init__.py`)."""
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path) -> set[str]:
    """Every jaxhoist module that the module at `path` imports, relative or absolute, at any depth, as
    absolute dotted names (`from . import x` names the module `x` where it is one)."""
    package = _module(path) if path.name == "__init__.py" else _module(path).rsplit(".", 1)[0]
    names = {_module(p) for p in MODULES}
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name.split(".")[0] == "jaxhoist"}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            if mod.split(".")[0] != "jaxhoist":
                continue
            out.add(mod)
            out |= {f"{mod}.{a.name}" for a in node.names if f"{mod}.{a.name}" in names}
    return out


def _in(module: str, prefix: str) -> bool:
    return module == prefix or module.startswith(prefix + ".")


def test_only_public_modules_lack_the_underscore():
    public = {p.name for p in PACKAGE.iterdir() if not p.name.startswith(("_", ".")) and p.name != "py.typed"}
    assert public == {"plots.py", "observables.py"}


def test_every_import_resolves_to_a_module():
    names = {_module(p) for p in MODULES}
    for path in MODULES:
        for mod in _imports(path):
            where = path.relative_to(PACKAGE)
            assert mod in names or mod.rsplit(".", 1)[0] in names, f"{where} imports {mod}"


def test_layers_import_one_way():
    allowed = {"_physics": {"_physics"}, "_io": {"_physics", "_io"}}
    allowed["_numerics"] = allowed["_io"] | {"_numerics"}
    allowed["_apps"] = allowed["_numerics"] | {"_apps"}
    for layer, ok in allowed.items():
        for path in (PACKAGE / layer).rglob("*.py"):
            layers = {m.split(".")[1] for m in _imports(path) if m.count(".") >= 1}
            bad = (layers & set(allowed)) - ok
            assert not bad, f"{path.relative_to(PACKAGE)} imports {bad}"


def test_the_cli_imports_the_library_never_the_reverse():
    for path in MODULES:
        if path.is_relative_to(PACKAGE / "_apps" / "cli") or path.name == "__main__.py":
            continue
        cli = {m for m in _imports(path) if _in(m, "jaxhoist._apps.cli")}
        assert not cli, f"{path.relative_to(PACKAGE)} imports the command line: {cli}"
    code = "import sys, jaxhoist; print(sorted(m for m in sys.modules if m.startswith('jaxhoist._apps.cli')))"
    loaded = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert loaded.strip() == "[]", f"import jaxhoist loads the command line: {loaded}"


def test_the_elastic_core_does_not_import_the_rigid_model():
    rigid = ("jaxhoist._physics.rigid", "jaxhoist._numerics.rigid")
    for layer in ("_physics", "_numerics"):
        for path in (PACKAGE / layer).rglob("*.py"):
            if path.is_relative_to(PACKAGE / layer / "rigid"):
                continue
            bad = {m for m in _imports(path) if any(_in(m, r) for r in rigid)}
            assert not bad, f"{path.relative_to(PACKAGE)} (elastic core) imports the rigid model: {bad}"


def test_every_family_has_a_face_of_imports_only():
    for family in FAMILIES:
        face = PACKAGE / family / "__init__.py"
        assert face.is_file(), f"{family} has no face"
        body = ast.parse(face.read_text()).body
        body = body[1:] if body and isinstance(body[0], ast.Expr) else body  # the docstring
        only_imports = all(isinstance(n, ast.ImportFrom) for n in body)
        assert only_imports, f"{family}/__init__.py holds more than imports"
        # a name of the face that is also a module's name would hide the module (`from pkg import mod`)
        names = {a.asname or a.name for n in body if isinstance(n, ast.ImportFrom) for a in n.names}
        modules = {p.stem for p in face.parent.glob("*.py")}
        assert not names & modules, f"{family}/__init__.py hides its modules {names & modules}"
    apps = {p.name for p in (PACKAGE / "_apps").iterdir() if p.suffix == ".py"}
    assert apps <= {"__init__.py", "simulate.py"}, f"_apps/ top level holds modules: {sorted(apps)}"


def test_underscore_names_stay_in_their_module():
    """A name another module imports is plain (privacy is the package's underscore); a leading underscore
    means private to its module. At most 10 exceptions, each with its reason in a comment on the line."""
    crossing = []
    for path in MODULES:
        lines = path.read_text().split("\n")
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.ImportFrom):
                continue
            if node.level or (node.module or "").startswith("jaxhoist"):
                for a in node.names:
                    if a.name.startswith("_") and not a.name.startswith("__"):
                        crossing.append((path.relative_to(PACKAGE), a.name, lines[node.end_lineno - 1]))
    assert len(crossing) <= 10, f"{len(crossing)} imports of _-names across modules: {crossing[:5]} ..."
    for where, name, line in crossing:
        assert "#" in line, f"{where} imports {name} without a reason comment"
