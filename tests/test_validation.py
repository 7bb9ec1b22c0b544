"""Invalid input is refused on the host, before compiling, with a `ScenarioError` that names the field.

Property tests (hypothesis, derandomized, few examples) start from the bundled presets' TOML dicts and
break exactly one thing."""

import copy
import re
from unittest import mock

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

import jaxhoist as jh
import jaxhoist.numerics.solve as solve_mod
from jaxhoist.physics.params import get_leaf, leaf_getter

PRESETS = ("paper-2.3", "paper-4.1", "paper-4.2")
FEW = settings(max_examples=25, derandomize=True, deadline=None)

# Numeric fields that must be > 0 or >= 0 (negative is invalid), as "table.field" of the scenario file.
NONNEGATIVE = ("t1", "gravity", "load.size", "load.density", "load.mass", "foundation.stiffness",
               "foundation.damping", "foundation.damping_onset", "foundation.friction_coefficient",
               "foundation.friction.deflection", "foundation.friction.breakaway_ratio",
               "foundation.friction.relaxation_time", "foundation.friction.regularisation_velocity",
               "rope.stiffness", "rope.damping", "rope.damping_onset", "rope.slack", "hoist.speed",
               "boom.tip_mass", "boom.stiffness", "boom.damping")
# Negative is fine for these (positions), but NaN and inf are not; a negative mass centre or rope point
# leaves the box, which is tested below.
ANY_SIGN = ("boom.tip_position",)
# Fields every scenario file must give (a missing one must be named).
REQUIRED = ("load.size", "foundation.stiffness", "foundation.damping", "foundation.friction_coefficient",
            "rope.stiffness", "rope.damping", "rope.attachment", "hoist.speed", "boom.tip_position",
            "boom.tip_mass", "boom.stiffness")


def _numeric_fields(d: dict, prefix: str = "") -> list[str]:
    out = []
    for k, v in d.items():
        path = f"{prefix}{k}"
        if isinstance(v, dict):
            out += _numeric_fields(v, path + ".")
        elif isinstance(v, int | float | list) and not isinstance(v, bool):
            out.append(path)
    return out


def _get(d: dict, path: str):
    *tables, key = path.split(".")
    for t in tables:
        d = d[t]
    return d, key


def _named(path: str) -> str:
    """A regex matching the field's dotted name as a whole word."""
    return r"(?<![\w.])" + re.escape(path) + r"(?![\w])"


def _core_must_not_run(*args, **kwargs):
    raise AssertionError("the jitted core was reached with an invalid scenario")


def load_and_simulate(d: dict):
    """What a user does: dict -> Scenario -> simulate, with the compiled core replaced by a trap."""
    with mock.patch.object(solve_mod, "_solve_jit", _core_must_not_run):
        jh.simulate(jh.scenario_from_dict(d, "test.toml"), 0.1)


def _expect_error_naming(d: dict, path: str):
    with pytest.raises(jh.ScenarioError) as info:
        load_and_simulate(d)
    assert re.search(_named(path), str(info.value)), (path, str(info.value))
    return str(info.value)


# ------------------------------------------------------------------------ bad numeric values


@FEW
@given(preset=st.sampled_from(PRESETS), data=st.data(),
       bad=st.sampled_from([-1.5, float("nan"), float("inf"), float("-inf")]))
def test_bad_number_names_its_field(preset_dicts, preset, data, bad):
    d = copy.deepcopy(preset_dicts[preset])
    fields = [f for f in _numeric_fields(d) if f in NONNEGATIVE + ANY_SIGN]
    path = data.draw(st.sampled_from(fields))
    assume(not (path in ANY_SIGN and np.isfinite(bad)))
    table, key = _get(d, path)
    if isinstance(table[key], list):
        i = data.draw(st.integers(0, len(table[key]) - 1))
        table[key][i] = bad
    else:
        table[key] = bad
    _expect_error_naming(d, path)


@FEW
@given(preset=st.sampled_from(PRESETS), axis=st.integers(0, 2),
       where=st.sampled_from(["negative", "beyond", "nan"]))
def test_rope_point_and_mass_centre_outside_the_box(preset_dicts, preset, axis, where):
    """B must lie on or in the box, C strictly inside it: each refused, naming its field."""
    for path in ("rope.attachment", "load.mass_centre"):
        d = copy.deepcopy(preset_dicts[preset])
        size = d["load"]["size"]
        table, key = _get(d, path)
        value = list(table.get(key, [s / 2 for s in size]))
        value[axis] = {"negative": -0.1, "beyond": size[axis] + 0.1, "nan": float("nan")}[where]
        table[key] = value
        _expect_error_naming(d, path)
    # On the box surface: allowed for B, refused for C (a mass centre on a face is not inside a body).
    d = copy.deepcopy(preset_dicts[preset])
    d["load"]["mass_centre"] = [s / 2 for s in d["load"]["size"]]
    d["load"]["mass_centre"][axis] = d["load"]["size"][axis]
    _expect_error_naming(d, "load.mass_centre")


# ------------------------------------------------------------------ misspelled, mistyped, missing


def _typo(key: str, kind: str, i: int) -> str:
    i = i % len(key)
    if kind == "drop":
        return key[:i] + key[i + 1:]
    if kind == "double":
        return key[:i] + key[i] + key[i:]
    j = min(i + 1, len(key) - 1)  # swap neighbours
    return key[:i] + key[j] + key[i] + key[j + 1:] if j > i else key[:-2] + key[-1] + key[-2]


@FEW
@given(preset=st.sampled_from(PRESETS), data=st.data(), kind=st.sampled_from(["drop", "double", "swap"]),
       i=st.integers(0, 30))
def test_misspelled_field_is_named_with_a_hint(preset_dicts, preset, data, kind, i):
    d = copy.deepcopy(preset_dicts[preset])
    path = data.draw(st.sampled_from(_numeric_fields(d)))
    table, key = _get(d, path)
    wrong = _typo(key, kind, i)
    assume(wrong != key and wrong not in table and len(wrong) > 0)
    table[wrong] = table.pop(key)
    wrong_path = (path.rsplit(".", 1)[0] + "." if "." in path else "") + wrong
    with pytest.raises(jh.ScenarioError) as info:
        load_and_simulate(d)
    msg = str(info.value)
    assert wrong_path in msg, (wrong_path, msg)
    if len(key) >= 5:  # a one-letter slip in a real word is close enough for a suggestion
        assert f"did you mean {key!r}" in msg, msg


@FEW
@given(preset=st.sampled_from(PRESETS), data=st.data(),
       wrong=st.sampled_from(["12.5", True, None, [1.0, 2.0], [[1.0, 2.0, 3.0]] * 3]))
def test_wrong_type_names_its_field(preset_dicts, preset, data, wrong):
    """A string, a boolean, a list of the wrong length or a matrix where a number or a 3-vector belongs
    (None stands for a value TOML cannot hold: it must be refused too)."""
    d = copy.deepcopy(preset_dicts[preset])
    path = data.draw(st.sampled_from(_numeric_fields(d)))
    table, key = _get(d, path)
    table[key] = copy.deepcopy(wrong)
    _expect_error_naming(d, path)


@pytest.mark.parametrize("path", ["rope.stiffness", "hoist.speed", "load.size", "boom.damping",
                                  "foundation.friction.regularisation_velocity"])
def test_table_where_a_value_belongs_names_its_field(preset_dicts, path):
    d = copy.deepcopy(preset_dicts["paper-4.2"])
    table, key = _get(d, path)
    table[key] = {"x": 1.0}
    _expect_error_naming(d, path)


@pytest.mark.parametrize("path", REQUIRED)
def test_missing_field_is_named(preset_dicts, path):
    for preset in PRESETS:
        d = copy.deepcopy(preset_dicts[preset])
        table, key = _get(d, path)
        del table[key]
        msg = _expect_error_naming(d, path)
        assert "missing" in msg


def test_mass_and_density_exactly_one(preset_dicts):
    d = copy.deepcopy(preset_dicts["paper-4.2"])
    del d["load"]["density"]
    with pytest.raises(jh.ScenarioError, match=r"mass.*density"):
        load_and_simulate(d)
    d["load"]["density"] = 850.0
    d["load"]["mass"] = 1000.0
    with pytest.raises(jh.ScenarioError, match=r"mass.*density"):
        load_and_simulate(d)


def test_unknown_table_and_law(preset_dicts):
    d = copy.deepcopy(preset_dicts["paper-4.2"])
    d["rpoe"] = d.pop("rope")
    with pytest.raises(jh.ScenarioError, match=r"rpoe.*did you mean 'rope'"):
        load_and_simulate(d)
    d = copy.deepcopy(preset_dicts["paper-4.2"])
    d["foundation"]["friction"]["law"] = "coulomb-regularised"
    with pytest.raises(jh.ScenarioError, match=r"foundation\.friction\.law"):
        load_and_simulate(d)


def test_presets_themselves_are_valid(preset_dicts):
    for preset in PRESETS:
        sc = jh.scenario_from_dict(copy.deepcopy(preset_dicts[preset]), f"{preset}.toml")
        assert sc.name == preset


# ------------------------------------------------------- leaves changed after construction


# Float leaves of a Scenario (paper-4.2: regularised Coulomb friction) that must be positive or
# non-negative, by dotted path.
LEAVES = ("load.mass", "load.size", "foundation.stiffness", "foundation.damping",
          "foundation.friction_coefficient", "foundation.friction.regularisation_velocity",
          "rope.stiffness", "rope.damping", "rope.slack", "hoist.speed", "boom.tip_mass", "boom.stiffness",
          "boom.damping", "gravity", "foundation.damping_onset", "rope.damping_onset")


@FEW
@given(path=st.sampled_from(LEAVES), value=st.sampled_from([-1.0, -1e-300, float("nan"), float("inf")]))
def test_replace_with_bad_value_is_caught_by_simulate(paper42, path, value):
    """`Scenario.replace` (like `eqx.tree_at`) skips `__init__`, so the checks must run again in simulate."""
    sc = paper42.replace(**{path: value * np.ones(np.shape(get_leaf(paper42, path)))})
    with mock.patch.object(solve_mod, "_solve_jit", _core_must_not_run):
        with pytest.raises(jh.ScenarioError, match=_named(path)):
            jh.simulate(sc, 0.1)


@pytest.mark.parametrize("path", ["foundation.friction_coefficient", "load.mass_centre", "rope.attachment"])
def test_float32_leaf_refused(paper42, path):
    leaf = get_leaf(paper42, path)
    getter = leaf_getter(path)
    sc = eqx.tree_at(getter, paper42, jnp.asarray(leaf, dtype=jnp.float32))
    with mock.patch.object(solve_mod, "_solve_jit", _core_must_not_run):
        with pytest.raises(jh.ScenarioError, match=_named(path)) as info:
            jh.simulate(sc, 0.1)
    assert "float32" in str(info.value) and "jax_enable_x64" in str(info.value)


def test_without_x64_a_clear_error(paper42):
    with jax.enable_x64(False):
        with pytest.raises(jh.Float64Error, match="jax_enable_x64"):
            jh.simulate(paper42, 0.1)
        with pytest.raises(jh.Float64Error, match="jax_enable_x64"):
            jh.load_scenario("paper-4.2")


def test_bad_times_and_options(paper42):
    with mock.patch.object(solve_mod, "_solve_jit", _core_must_not_run):
        for kw, word in [(dict(t1=-1.0), "t1"), (dict(t1=float("nan")), "t1"),
                         (dict(ts=np.array([0.1, 0.2])), "ts"), (dict(ts=np.array([0.0, 0.2, 0.1])), "ts"),
                         (dict(t1=1.0, rtol=-1e-6), "rtol"), (dict(t1=1.0, max_steps=0), "max_steps"),
                         (dict(t1=1.0, adjoint="backward"), "adjoint"), (dict(t1=1.0, n_save=1), "n_save")]:
            with pytest.raises(jh.ScenarioError, match=word):
                jh.simulate(paper42, **kw)
