"""Scenario files (TOML) -> checked `Scenario`. Every field, its unit and default is listed in `SCHEMA`;
unknown keys get a "did you mean" hint, and every error names the file, table and field.

A scenario file (see `presets/paper-4.2.toml` for a commented one):

    name = "my-lift"         # label
    t1 = 25.0                # default simulated time [s]
    gravity = 9.81           # g [m/s^2]

    [load]        size, mass | density, mass_centre, inertia
    [foundation]  stiffness, damping, friction_coefficient
    [foundation.friction]  law = "regularised-coulomb" (regularisation_velocity; the default)
                           | "bristle" (deflection, breakaway_ratio, relaxation_time)
    [rope]        stiffness, damping, attachment, slack
    [hoist]       law = "constant-speed" (speed) | "ramped" (speed, ramp_time, travel)
                  | "knots" (times, speeds, max_speed, travel)
    [boom]        tip_position, tip_mass, stiffness, damping
"""

from __future__ import annotations

import difflib
import math
import tomllib
from importlib import resources
from pathlib import Path
from typing import Any

import equinox as eqx

from .._errors import ScenarioError, require_x64
from .._physics import params as P
from .._physics.checks import OPT_IN
from .._physics.paths import get_leaf
from .validate import brief, parse_list, parse_number, read_text

# field -> (unit, required, kind) where kind is "float", "vec3", "list" (of floats), "mat33", "str" or
# "float|vec3".
_REQ, _OPT = True, False
SCHEMA: dict[str, dict[str, tuple[str, bool, str]]] = {
    "": {
        "name": ("-", _OPT, "str"),
        "description": ("-", _OPT, "str"),
        "t1": ("s", _OPT, "float"),
        "gravity": ("m/s^2", _OPT, "float"),
    },
    "load": {
        "size": ("m", _REQ, "vec3"),
        "mass": ("kg", _OPT, "float"),
        "density": ("kg/m^3", _OPT, "float"),
        "mass_centre": ("m", _OPT, "vec3"),
        "inertia": ("kg m^2", _OPT, "mat33"),
    },
    "foundation": {
        "stiffness": ("N/m", _REQ, "float"),
        "damping": ("N s/m", _REQ, "float"),
        "friction_coefficient": ("-", _REQ, "float"),
        "damping_onset": ("m", _OPT, "float"),
    },
    "foundation.friction:bristle": {
        "law": ("-", _REQ, "str"),
        "deflection": ("m", _OPT, "float"),
        "breakaway_ratio": ("-", _OPT, "float"),
        "relaxation_time": ("s", _OPT, "float"),
    },
    "foundation.friction:regularised-coulomb": {
        "law": ("-", _REQ, "str"),
        "regularisation_velocity": ("m/s", _OPT, "float"),
    },
    "rope": {
        "stiffness": ("N/m", _REQ, "float"),
        "damping": ("N s/m", _REQ, "float"),
        "attachment": ("m", _REQ, "vec3"),
        "slack": ("m", _OPT, "float"),
        "damping_onset": ("m", _OPT, "float"),
    },
    "hoist:constant-speed": {"law": ("-", _OPT, "str"), "speed": ("m/s", _REQ, "float")},
    "hoist:ramped": {
        "law": ("-", _REQ, "str"),
        "speed": ("m/s", _REQ, "float"),
        "ramp_time": ("s", _OPT, "float"),
        "travel": ("m", _OPT, "float"),
    },
    "hoist:knots": {
        "law": ("-", _REQ, "str"),
        "times": ("s", _REQ, "list"),
        "speeds": ("m/s", _REQ, "list"),
        "max_speed": ("m/s", _OPT, "float"),
        "travel": ("m", _OPT, "float"),
    },
    "boom": {
        "tip_position": ("m", _REQ, "vec3"),
        "tip_mass": ("kg", _REQ, "float"),
        "stiffness": ("N/m", _REQ, "float|vec3"),
        "damping": ("N s/m", _OPT, "float|vec3"),
    },
}
FRICTION_LAWS = ("bristle", "regularised-coulomb")
HOIST_LAWS = ("constant-speed", "ramped", "knots")
PRESETS = ("paper-2.3", "paper-4.1", "paper-4.2", "paper-4.3")


def preset_names() -> tuple[str, ...]:
    return PRESETS


def _hint(word: str, options) -> str:
    close = difflib.get_close_matches(word, list(options), n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


class _Reader:
    def __init__(self, source: str):
        self.source = source

    def error(self, table: str, msg: str) -> ScenarioError:
        where = f"table [{table}]" if table else "top level"
        return ScenarioError(f"{msg} [{self.source}, {where}]")

    def table(
        self, data: dict, table: str, schema_key: str | None = None, subtables: tuple[str, ...] = ()
    ) -> dict[str, Any]:
        """Check one table's keys and value types against SCHEMA; return {field: converted value}.
        `subtables` are the keys that hold a table read separately."""
        schema = SCHEMA[schema_key or table]
        out = {}
        for key, value in data.items():
            if isinstance(value, dict) and key in subtables:
                continue
            if isinstance(value, dict) and key in schema:
                unit, _, kind = schema[key]
                raise self.error(
                    table,
                    f"{_dotted(table, key)} must be a {kind.replace('|', ' or ')} [{unit}], "
                    f"got a table {brief(value)}",
                )
            if isinstance(value, dict):
                allowed = sorted(schema) + list(subtables)
                raise self.error(
                    table, f"unknown table [{_dotted(table, key)}]{_hint(key, allowed)}; allowed: {allowed}"
                )
            if key not in schema:
                raise self.error(
                    table,
                    f"unknown field {_dotted(table, key)!r}{_hint(key, schema)}; allowed: {sorted(schema)}",
                )
            unit, _, kind = schema[key]
            out[key] = self._convert(table, key, value, kind, unit)
        for key, (unit, required, _) in schema.items():
            if required and key not in data:
                raise self.error(table, f"missing field {_dotted(table, key)!r} [{unit}]")
        return out

    def _convert(self, table, key, value, kind, unit):
        name = _dotted(table, key)

        def num(v):
            if isinstance(v, bool) or not isinstance(v, int | float):
                raise self.error(table, f"{name} must be a number [{unit}], got {brief(v)}")
            try:
                return float(v)
            except OverflowError:
                raise self.error(
                    table, f"{name} = {brief(v)} is an integer too large for a float [{unit}]"
                ) from None

        if kind == "str":
            if not isinstance(value, str):
                raise self.error(table, f"{name} must be a string, got {brief(value)}")
            return value
        if kind == "float":
            return num(value)
        if kind == "float|vec3" and not isinstance(value, list):
            return num(value)
        if kind in ("vec3", "float|vec3"):
            if not isinstance(value, list) or len(value) != 3:
                raise self.error(table, f"{name} must be a list of 3 numbers [{unit}], got {brief(value)}")
            return [num(v) for v in value]
        if kind == "list":
            if not isinstance(value, list) or not value:
                raise self.error(table, f"{name} must be a list of numbers [{unit}], got {brief(value)}")
            return [num(v) for v in value]
        if kind == "mat33":
            if not (
                isinstance(value, list)
                and len(value) == 3
                and all(isinstance(r, list) and len(r) == 3 for r in value)
            ):
                raise self.error(table, f"{name} must be a 3x3 list of lists [{unit}], got {brief(value)}")
            return [[num(v) for v in r] for r in value]
        raise AssertionError(kind)


def _dotted(table: str, key: str) -> str:
    return f"{table}.{key}" if table else key


def _law(reader: _Reader, data: dict, table: str, laws, default: str | None) -> str:
    law = data.get("law", default)
    if law is None:
        raise reader.error(table, f"missing field {table}.law; one of {list(laws)}")
    if law not in laws:
        raise reader.error(
            table,
            f"{table}.law = {brief(law)} is not a known law{_hint(str(law)[:100], laws)}; "
            f"one of {list(laws)}",
        )
    return law


#: The plausible range of `load.density` [kg/m^3] (not a leaf: the mass ρabc is, with a range of its own).
DENSITY_RANGE = (1e-1, 1e5)


def scenario_from_dict(data: dict, source: str = "<dict>", *, allow_implausible: bool = False) -> P.Scenario:
    """Build a checked `Scenario` from the plain dict of a scenario file.

    **Arguments**
    - `data`: the dict (tables `load`, `foundation`, `rope`, `hoist`, `boom`; see `SCHEMA`).
    - `source`: where it came from, for the messages.
    - `allow_implausible`: accept values outside the parameters' plausible ranges (see
      `Scenario.allow_implausible`); the solve's own checks still apply.

    **Returns** the `Scenario`.

    **Raises** `ScenarioError` naming the source, table and field.
    """
    require_x64()
    r = _Reader(source)
    tables = ("load", "foundation", "rope", "hoist", "boom")
    for key, value in data.items():
        if isinstance(value, dict) and key not in tables:
            raise r.error("", f"unknown table [{key}]{_hint(key, tables)}; tables are {list(tables)}")
    top = r.table(data, "", subtables=tables)
    for t in tables:
        if t not in data:
            raise r.error("", f"missing table [{t}]")
        if not isinstance(data[t], dict):
            raise r.error("", f"{t} must be a table [{t}], got {brief(data[t])}")

    try:
        ld = r.table(data["load"], "load")
        try:
            _check_density(ld.get("density"), allow_implausible)
        except ScenarioError as e:
            raise r.error("load", str(e)) from None
        load = P.Load(
            ld["size"],
            ld.get("mass"),
            density=ld.get("density"),
            mass_centre=ld.get("mass_centre"),
            inertia=ld.get("inertia"),
        )
        fr_data = data["foundation"].get("friction", {"law": "regularised-coulomb"})
        if not isinstance(fr_data, dict):
            raise r.error(
                "foundation",
                f"foundation.friction must be a table [foundation.friction], got {brief(fr_data)}",
            )
        law = _law(r, fr_data, "foundation.friction", FRICTION_LAWS, None)
        fr = r.table(fr_data, "foundation.friction", f"foundation.friction:{law}")
        fr.pop("law")
        friction = P.BristleFriction(**fr) if law == "bristle" else P.RegularisedCoulomb(**fr)
        fd = r.table(data["foundation"], "foundation", subtables=("friction",))
        foundation = P.Foundation(
            fd["stiffness"],
            fd["damping"],
            fd["friction_coefficient"],
            friction,
            fd.get("damping_onset", 1e-4),
        )
        rp = r.table(data["rope"], "rope")
        rope = P.Rope(
            rp["stiffness"],
            rp["damping"],
            rp["attachment"],
            rp.get("slack", 0.0),
            rp.get("damping_onset", 1e-4),
        )
        hlaw = _law(r, data["hoist"], "hoist", HOIST_LAWS, "constant-speed")
        hs = r.table(data["hoist"], "hoist", f"hoist:{hlaw}")
        hs.pop("law", None)
        hoist = {"constant-speed": P.ConstantSpeedHoist, "ramped": P.RampedHoist, "knots": P.KnotHoist}[hlaw](
            **hs
        )
        bm = r.table(data["boom"], "boom")
        boom = P.Boom(bm["tip_position"], bm["tip_mass"], bm["stiffness"], bm.get("damping", 0.0))
        t1 = top.get("t1", 10.0)
        if not (math.isfinite(t1) and t1 > 0):
            raise ScenarioError(f"t1 must be a positive finite time [s], got {t1}")
        return P.Scenario(
            load,
            foundation,
            rope,
            hoist,
            boom,
            gravity=top.get("gravity", 9.81),
            name=top.get("name", Path(source).stem),
            t1=t1,
            description=top.get("description", ""),
            allow_implausible=allow_implausible,
        )
    except ScenarioError as e:
        msg = str(e)
        if f"[{source}" in msg:
            raise
        raise ScenarioError(f"{msg} [{source}]") from None


def parse_overrides(items) -> dict[str, float | list]:
    """Command-line overrides `["rope.stiffness=1e7", "load.mass_centre=[1, 2.5, 1]"]` -> {path: value}.

    Numbers are read strictly (`jaxhoist._io.validate.parse_number`: `0_3` is refused, not read as 3);
    lists in JSON syntax, nested at most 2 deep, or a vector as comma-separated numbers (`1,2.5,1`).

    **Raises** `ScenarioError` naming `--set` and the path.
    """
    out = {}
    for item in items:
        path, sep, value = str(item).partition("=")
        path = path.strip()
        if not sep or not path:
            raise ScenarioError(
                f"--set expects PATH=VALUE (e.g. foundation.friction_coefficient=0.3), got {brief(item)}"
            )
        where = f"--set {brief(path, 60)}"
        v = value.strip()
        if v.startswith("["):
            out[path] = parse_list(v, where)
            continue
        try:  # a number, or a vector typed as x,y,z
            out[path] = [parse_number(x, where) for x in v.split(",")] if "," in v else parse_number(v, where)
        except ScenarioError:
            raise ScenarioError(
                f"{where}: expected a number like 0.3 or 1.5e7, or for a vector field x,y,z like 1,2.5,1 "
                f"(or [1, 2.5, 1]), got {brief(value)}"
            ) from None
    return out


def _check_density(rho, allow_implausible: bool) -> None:
    """Refuse a load density ρ [kg/m^3] outside `DENSITY_RANGE` unless `allow_implausible` (a file's
    `density` and `--set load.density` alike; `Load` itself refuses ρ <= 0 and NaN)."""
    lo, hi = DENSITY_RANGE
    implausible = rho is not None and math.isfinite(rho) and rho > 0 and not lo <= rho <= hi
    if implausible and not allow_implausible:
        raise ScenarioError(
            f"load.density = {rho:g} kg/m^3 is outside its plausible range {lo:g} to {hi:g} kg/m^3 "
            f"(a hollow container ~100, steel 7850, osmium 22600); {OPT_IN}"
        )


def apply_overrides(scenario: P.Scenario, items) -> tuple[P.Scenario, dict]:
    """A scenario with `--set PATH=VALUE` items applied and checked; errors name the path and say
    "[from --set]". PATH is a leaf's dotted path (`Scenario.replace`), or `load.density` [kg/m^3], which
    sets the mass to ρabc of the box's size (after a `load.size` of the same command line), as a scenario
    file's `density` does (`load.size` alone keeps the mass), or `load.inertia` [kg m²] where the scenario
    has none (as a file's `inertia`). **Returns** `(scenario, {path: value})`."""
    overrides = parse_overrides(items or [])
    leaves = dict(overrides)
    density = leaves.pop("load.density", None)
    # an inertia where the scenario has none (the uniform box's is then computed): a new Load, not a leaf
    unset = scenario.load.inertia is None and "load.inertia" in leaves
    inertia = leaves.pop("load.inertia") if unset else None
    try:
        if density is not None and "load.mass" in leaves:
            raise ScenarioError("load: give load.mass [kg] or load.density [kg/m^3], not both")
        if density is not None and not isinstance(density, float):
            raise ScenarioError(f"load.density: expected one number [kg/m^3], got {brief(density)}")
        for path in leaves:
            get_leaf(scenario, path)  # raises ScenarioError naming a bad path
        if leaves:
            scenario = scenario.replace(**leaves)
        if density is not None:  # m = ρabc, checked as the file's density is
            _check_density(density, scenario.allow_implausible)
            mass = P.Load(scenario.load.size, density=density).mass
            scenario = scenario.replace(**{"load.mass": float(mass)})
        if inertia is not None:
            ld = scenario.load
            load = P.Load(ld.size, ld.mass, mass_centre=ld.mass_centre, inertia=inertia)
            scenario = eqx.tree_at(lambda s: s.load, scenario, load)
        if overrides:
            scenario.check()
    except ScenarioError as e:
        raise ScenarioError(f"{e} [from --set]") from None
    return scenario, overrides


def load_scenario(name_or_path: str | Path, *, allow_implausible: bool = False) -> P.Scenario:
    """A `Scenario` from a bundled preset name (`paper-2.3`, `paper-4.1`, `paper-4.2`, `paper-4.3`) or a
    TOML path.

    With `allow_implausible`, values outside the parameters' plausible ranges are accepted (see
    `Scenario.allow_implausible`; the solve's own checks still apply); without it they are refused.

    **Raises** `ScenarioError` naming the file and field for any invalid content (a folder, non-UTF-8
    bytes, invalid TOML, nesting too deep, integers too large for a float, unknown or missing fields, bad
    values), before compiling.
    """
    text, source = _read(name_or_path)
    try:
        data = tomllib.loads(text)
    except RecursionError:
        raise ScenarioError(f"{source}: not valid TOML: arrays or tables nested too deeply") from None
    except tomllib.TOMLDecodeError as e:
        raise ScenarioError(f"{source}: not valid TOML: {e}") from None
    except ValueError as e:  # an integer of more than 4300 digits (Python's int-from-text limit)
        raise ScenarioError(f"{source}: {_huge_integer(text) or e}") from None
    return scenario_from_dict(data, source, allow_implausible=allow_implausible)


def _huge_integer(text: str) -> str | None:
    """Where a scenario text holds an integer too long to read: "line N: key = <integer of D digits> ..."."""
    import re

    m = re.search(r"[0-9_]{4000,}", text)
    if m is None:
        return None
    line_no = text.count("\n", 0, m.start()) + 1
    line = text[text.rfind("\n", 0, m.start()) + 1 : m.start()]
    key = re.match(r"\s*([\w.\"'-]+)\s*=", line)
    name = f"{key.group(1)} = " if key else ""
    return (
        f"line {line_no}: {name}an integer of {m.end() - m.start()} digits, too large for a float "
        f"(write numbers like 1.5e7)"
    )


def _read(name_or_path) -> tuple[str, str]:
    s = str(name_or_path)
    if s in PRESETS:
        return resources.files("jaxhoist._io.presets").joinpath(f"{s}.toml").read_text(), f"{s}.toml"
    path = Path(s)
    if not path.exists() and not path.is_symlink():
        raise ScenarioError(
            f"no scenario file {brief(s)} and no preset of that name{_hint(s[:100], PRESETS)}; "
            f"presets are {list(PRESETS)}"
        )
    return read_text(path, "scenario file"), str(path)
