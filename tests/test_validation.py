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
from _inputs import BIFURCATION_MU
from hypothesis import assume, given, settings
from hypothesis import strategies as st

import jaxhoist as jh
import jaxhoist._numerics.solve as solve_mod
from jaxhoist._physics.paths import get_leaf, leaf_getter

PRESETS = ("paper-2.3", "paper-4.1", "paper-4.2", "paper-4.3")
FEW = settings(max_examples=25, derandomize=True, deadline=None)

# Numeric fields that must be > 0 or >= 0 (negative is invalid), as "table.field" of the scenario file.
NONNEGATIVE = (
    "t1",
    "gravity",
    "load.size",
    "load.density",
    "load.mass",
    "foundation.stiffness",
    "foundation.damping",
    "foundation.damping_onset",
    "foundation.friction_coefficient",
    "foundation.friction.deflection",
    "foundation.friction.breakaway_ratio",
    "foundation.friction.relaxation_time",
    "foundation.friction.regularisation_velocity",
    "rope.stiffness",
    "rope.damping",
    "rope.damping_onset",
    "rope.slack",
    "hoist.speed",
    "boom.tip_mass",
    "boom.stiffness",
    "boom.damping",
)
# Negative is fine for these (positions), but NaN and inf are not; a negative mass centre or rope point
# leaves the box, which is tested below.
ANY_SIGN = ("boom.tip_position",)
# Fields every scenario file must give (a missing one must be named).
REQUIRED = (
    "load.size",
    "foundation.stiffness",
    "foundation.damping",
    "foundation.friction_coefficient",
    "rope.stiffness",
    "rope.damping",
    "rope.attachment",
    "hoist.speed",
    "boom.tip_position",
    "boom.tip_mass",
    "boom.stiffness",
)


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
    with mock.patch.object(solve_mod, "_core", _core_must_not_run):
        jh.simulate(jh.scenario_from_dict(d, "test.toml"), 0.1)


def _expect_error_naming(d: dict, path: str):
    with pytest.raises(jh.ScenarioError) as info:
        load_and_simulate(d)
    assert re.search(_named(path), str(info.value)), (path, str(info.value))
    return str(info.value)


# ------------------------------------------------------------------------ bad numeric values


@FEW
@given(
    preset=st.sampled_from(PRESETS),
    data=st.data(),
    bad=st.sampled_from([-1.5, float("nan"), float("inf"), float("-inf")]),
)
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
@given(
    preset=st.sampled_from(PRESETS),
    axis=st.integers(0, 2),
    where=st.sampled_from(["negative", "beyond", "nan"]),
)
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
        return key[:i] + key[i + 1 :]
    if kind == "double":
        return key[:i] + key[i] + key[i:]
    j = min(i + 1, len(key) - 1)  # swap neighbours
    return key[:i] + key[j] + key[i] + key[j + 1 :] if j > i else key[:-2] + key[-1] + key[-2]


@FEW
@given(
    preset=st.sampled_from(PRESETS),
    data=st.data(),
    kind=st.sampled_from(["drop", "double", "swap"]),
    i=st.integers(0, 30),
)
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
@given(
    preset=st.sampled_from(PRESETS),
    data=st.data(),
    wrong=st.sampled_from(["12.5", True, None, [1.0, 2.0], [[1.0, 2.0, 3.0]] * 3]),
)
def test_wrong_type_names_its_field(preset_dicts, preset, data, wrong):
    """A string, a boolean, a list of the wrong length or a matrix where a number or a 3-vector belongs
    (None stands for a value TOML cannot hold: it must be refused too)."""
    d = copy.deepcopy(preset_dicts[preset])
    path = data.draw(st.sampled_from(_numeric_fields(d)))
    table, key = _get(d, path)
    table[key] = copy.deepcopy(wrong)
    _expect_error_naming(d, path)


@pytest.mark.parametrize(
    "path",
    [
        "rope.stiffness",
        "hoist.speed",
        "load.size",
        "boom.damping",
        "foundation.friction.regularisation_velocity",
    ],
)
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
LEAVES = (
    "load.mass",
    "load.size",
    "foundation.stiffness",
    "foundation.damping",
    "foundation.friction_coefficient",
    "foundation.friction.regularisation_velocity",
    "rope.stiffness",
    "rope.damping",
    "rope.slack",
    "hoist.speed",
    "boom.tip_mass",
    "boom.stiffness",
    "boom.damping",
    "gravity",
    "foundation.damping_onset",
    "rope.damping_onset",
)


@FEW
@given(path=st.sampled_from(LEAVES), value=st.sampled_from([-1.0, -1e-300, float("nan"), float("inf")]))
def test_replace_with_bad_value_is_caught_by_simulate(paper42, path, value):
    """`Scenario.replace` (like `eqx.tree_at`) skips `__init__`, so the checks must run again in simulate."""
    sc = paper42.replace(**{path: value * np.ones(np.shape(get_leaf(paper42, path)))})
    with mock.patch.object(solve_mod, "_core", _core_must_not_run):
        with pytest.raises(jh.ScenarioError, match=_named(path)):
            jh.simulate(sc, 0.1)


@pytest.mark.parametrize("path", ["foundation.friction_coefficient", "load.mass_centre", "rope.attachment"])
def test_float32_leaf_refused(paper42, path):
    leaf = get_leaf(paper42, path)
    getter = leaf_getter(path)
    sc = eqx.tree_at(getter, paper42, jnp.asarray(leaf, dtype=jnp.float32))
    with mock.patch.object(solve_mod, "_core", _core_must_not_run):
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
    with mock.patch.object(solve_mod, "_core", _core_must_not_run):
        for kw, word in [
            (dict(times=-1.0), "t1"),
            (dict(times=float("nan")), "t1"),
            (dict(times=np.array([0.1, 0.2])), "ts"),
            (dict(times=np.array([0.0, 0.2, 0.1])), "ts"),
            (dict(times=1.0, options=dict(rtol=-1e-6)), "rtol"),
            (dict(times=1.0, options=dict(max_steps=0)), "max_steps"),
            (dict(times=dict(t1=1.0, n=1)), "n "),
            (dict(times=dict(t1=1.0, n=2.0)), "n "),
        ]:
            with pytest.raises(jh.ScenarioError, match=word):
                if "options" in kw:
                    kw = {**kw, "options": jh.SolverOptions(**kw["options"])}
                if isinstance(kw["times"], dict):
                    kw = {**kw, "times": jh.Times(**kw["times"])}
                jh.simulate(paper42, **kw)


# ------------------------------------------------------------------------------------ adversarial inputs
# Every bad input ends in one `ScenarioError` line of bounded length naming the field (exit 2 from the
# CLI), before anything is compiled; nothing else escapes (no OverflowError, UnicodeDecodeError,
# RecursionError, AttributeError, TypeError from a pytree, shape error while compiling).

MAX_MESSAGE = 600  # jaxhoist._errors.MAX_MESSAGE_CHARS: a capped error line is at most this long


def _preset_text(name: str = "paper-4.2") -> str:
    from importlib import resources

    return resources.files("jaxhoist._io.presets").joinpath(f"{name}.toml").read_text()


def _one_bounded_line(msg: str) -> str:
    assert "\n" not in msg and len(msg) <= MAX_MESSAGE, (len(msg), msg[:200])
    return msg


def _load_error(path) -> str:
    with pytest.raises(jh.ScenarioError) as info:
        jh.load_scenario(path)
    return _one_bounded_line(str(info.value))


@pytest.mark.parametrize(
    "old,new,field",
    [
        ("t1 = 25.0", "t1 = 1" + "0" * 400, "t1"),
        ("tip_mass = 500.0", "tip_mass = " + "9" * 330, "boom.tip_mass"),
        ("size = [2.5, 6.0, 2.5]", "size = [2.5, 1" + "0" * 320 + ", 2.5]", "load.size"),
        ("speed = 0.3", "speed = " + "7" * 5000, "speed"),  # beyond Python's 4300-digit int conversion limit
    ],
)
def test_integer_too_large_for_a_float_names_its_field(tmp_path, old, new, field):
    path = tmp_path / "big.toml"
    text = _preset_text()
    assert old in text
    path.write_text(text.replace(old, new, 1))
    msg = _load_error(path)
    assert re.search(_named(field), msg) and str(path) in msg, msg


@pytest.mark.parametrize("encoding", ["latin-1", "utf-16", "bad-utf-8"])
def test_non_utf8_scenario_file_is_refused_with_the_encoding_named(tmp_path, encoding):
    text = _preset_text().replace("our choice", "ça, choix à nous")
    path = tmp_path / "enc.toml"
    if encoding == "bad-utf-8":
        path.write_bytes(text.encode() + b"\n# \xff\xfe\xfa\n")
    else:
        path.write_bytes(text.encode(encoding, errors="replace"))  # ρ, μ have no Latin-1 code
    msg = _load_error(path)
    assert "UTF-8" in msg and str(path) in msg, msg
    if encoding == "utf-16":
        assert "UTF-16" in msg, msg
    else:
        assert re.search(r"line \d+", msg), msg


def test_utf8_bom_is_accepted(tmp_path):
    path = tmp_path / "bom.toml"
    path.write_bytes(b"\xef\xbb\xbf" + _preset_text().encode())
    assert float(jh.load_scenario(path).foundation.friction_coefficient) == 0.25


def test_deeply_nested_array_is_refused(tmp_path):
    path = tmp_path / "deep.toml"
    path.write_text(_preset_text() + "\nx = " + "[" * 100_000 + "]" * 100_000 + "\n")
    msg = _load_error(path)
    assert "nested" in msg and str(path) in msg, msg
    # nested one level too deep for a 3-vector: refused naming the field, with a short repr
    path.write_text(_preset_text().replace("size = [2.5, 6.0, 2.5]", "size = " + "[" * 50 + "]" * 50))
    assert re.search(_named("load.size"), _load_error(path))


def test_huge_array_gives_a_short_message(tmp_path):
    path = tmp_path / "huge.toml"
    path.write_text(_preset_text().replace("speed = 0.3", "speed = [" + ", ".join(["0.3"] * 200_000) + "]"))
    msg = _load_error(path)
    assert re.search(_named("hoist.speed"), msg) and str(path) in msg, msg


def test_scenario_path_that_is_a_folder(tmp_path):
    msg = _load_error(tmp_path)
    assert "folder" in msg and str(tmp_path) in msg, msg


def test_error_messages_are_capped_and_on_one_line():
    e = jh.ScenarioError("load.size must be a list of 3 numbers, got " + "[0.3, " * 2_000_000 + "] [x.toml]")
    msg = _one_bounded_line(str(e))
    assert msg.startswith("load.size must be") and msg.endswith("] [x.toml]") and "omitted" in msg
    assert str(jh.ScenarioError("two\nlines")) == "two lines"


# ---- --set values and paths


def _set_error(paper42, item: str) -> str:
    from jaxhoist._io.scenario import apply_overrides

    with mock.patch.object(solve_mod, "_core", _core_must_not_run):
        with pytest.raises(jh.ScenarioError) as info:
            apply_overrides(paper42, [item])
    return _one_bounded_line(str(info.value))


@pytest.mark.parametrize(
    "item,field",
    [
        ("t1=5", "t1"),  # a static setting, not a float leaf: use --t1
        ("name=5", "name"),
        ("hoist.speed=[0.3,0.3,0.3]", "hoist.speed"),  # a vector where a number belongs
        ("load.mass_centre=[1.0, 2.5]", "load.mass_centre"),
        ("load.mass.real=5", "load.mass"),  # an attribute of the array, not a field
        ("load.mass.shape=5", "load.mass"),
        ("foundation._check=5", "foundation"),
        ("foundation.friction_coefficient=0_3", "foundation.friction_coefficient"),  # not 3: refused
        ("foundation.friction_coefficient=0x1p-2", "foundation.friction_coefficient"),
        ("rope.stiffness=1e7 ", None),  # fine (whitespace): no error expected
        ("hoist.speed=" + "[" * 5000 + "]" * 5000, "hoist.speed"),
        ("hoist.speed=1" + "0" * 400, "hoist.speed"),
        ("load.size=[2.5, 1" + "0" * 400 + ", 2.5]", "load.size"),
        ("load.size=[" + ", ".join(["1.0"] * 300_000) + "]", "load.size"),
    ],
)
def test_bad_override_names_its_field(paper42, item, field):
    from jaxhoist._io.scenario import apply_overrides

    if field is None:
        sc, over = apply_overrides(paper42, [item])
        assert float(sc.rope.stiffness) == 1e7 and over == {"rope.stiffness": 1e7}
        return
    msg = _set_error(paper42, item)
    assert re.search(_named(field), msg) and "--set" in msg, msg
    if field == "t1":
        assert "--t1" in msg, msg


# ---- physically absurd but finite values


@pytest.mark.parametrize(
    "path,value,field",
    [
        ("foundation.stiffness", 1e-300, "foundation.stiffness"),
        ("foundation.stiffness", 1.0, "foundation.stiffness"),  # the weight would sink the box below ground
        ("rope.stiffness", 1e300, "rope.stiffness"),
        ("load.mass", 1e300, "load.mass"),
        ("gravity", 1e-200, "gravity"),
    ],
)
def test_absurd_but_finite_values_are_flagged(paper42, path, value, field):
    with mock.patch.object(solve_mod, "_core", _core_must_not_run):
        with pytest.raises(jh.ScenarioError) as info:
            jh.simulate(paper42.replace(**{path: value}), 0.1)
    msg = _one_bounded_line(str(info.value))
    assert re.search(_named(field), msg) and "plausib" in msg, msg


def test_absurd_density_in_a_file_is_flagged(tmp_path):
    path = tmp_path / "dense.toml"
    path.write_text(_preset_text().replace("density = 850.0", "density = 1e300"))
    msg = _load_error(path)
    assert re.search(_named("load.density"), msg) and "plausib" in msg, msg


def test_plausible_extremes_still_accepted(paper42):
    """A stiff ground and rope (rigid limit), a feather-light box on soft ground: plausible, accepted.
    (The tip mass is the lower end of its plausible range, 1 g: 1e-6 kg, accepted by the earlier
    magnitude check, is now refused as implausible, see tests/test_self_checks.py.)"""
    paper42.replace(**{"foundation.stiffness": 1e12, "rope.stiffness": 1e12, "boom.tip_mass": 1e-3}).check()
    paper42.replace(**{"load.mass": 1.0, "foundation.stiffness": 1e3}).check()


# ---- the Python API refuses what the CLI refuses


@pytest.mark.parametrize(
    "path,value",
    [
        ("foundation.friction_coefficient", -0.1),
        ("rope.stiffness", -5.0),
        ("hoist.speed", float("nan")),
        ("foundation.stiffness", 1e-300),
    ],
)
def test_api_and_cli_give_the_same_message(paper42, path, value):
    cli_msg = _set_error(paper42, f"{path}={value}")
    with mock.patch.object(solve_mod, "_core", _core_must_not_run):
        with pytest.raises(jh.ScenarioError) as info:
            jh.simulate(paper42.replace(**{path: value}), 0.1)
    assert cli_msg == f"{info.value} [from --set]"
    assert re.search(_named(path), cli_msg)


@pytest.mark.parametrize(
    "path,hint",
    [
        ("foundation.friction_coeficient", "friction_coefficient"),
        ("fundation.stiffness", "foundation"),
        ("rope.stifness", "stiffness"),
    ],
)
def test_replace_typo_suggests_the_closest_field(paper42, path, hint):
    with pytest.raises(jh.ScenarioError) as info:
        paper42.replace(**{path: 0.3})
    assert f"did you mean {hint!r}" in str(info.value) and path in str(info.value)


def test_replace_refuses_wrong_shapes_and_types(paper42):
    with pytest.raises(jh.ScenarioError, match=_named("hoist.speed")):
        paper42.replace(**{"hoist.speed": [0.3, 0.3, 0.3]})
    with pytest.raises(jh.ScenarioError, match=_named("rope.stiffness")):
        paper42.replace(**{"rope.stiffness": "stiff"})
    # a scalar for a 3-vector broadcasts, as the constructor does
    sc = paper42.replace(**{"boom.stiffness": 4e6})
    assert np.shape(sc.boom.stiffness) == (3,) and float(sc.boom.stiffness[2]) == 4e6


def test_t1_contradicting_ts_is_refused():
    from jaxhoist._numerics.times import check_times

    with pytest.raises(jh.ScenarioError, match=r"t1.*ts"):
        check_times(1.0, [0.0, 0.02, 0.05])
    check_times(0.05, np.array([0.0, 0.02, 0.05]))
    check_times(None, [0.0, 0.05])
    check_times(1.0, None)


def test_simulate_refuses_t1_contradicting_ts(paper42):
    with mock.patch.object(solve_mod, "_core", _core_must_not_run):
        with pytest.raises(jh.ScenarioError, match=r"t1.*ts"):
            jh.simulate(paper42, jh.Times(1.0, ts=np.array([0.0, 0.02, 0.05])))


def test_forward_mode_through_a_reverse_adjoint_says_what_to_do():
    from jaxhoist._errors import forward_mode_hint

    @jax.custom_vjp
    def f(x):
        return x**2

    f.defvjp(lambda x: (x**2, x), lambda x, g: (2 * x * g,))
    with pytest.raises(TypeError, match=r"adjoint=diffrax\.ForwardMode\(\)"):
        with forward_mode_hint():
            jax.jacfwd(f)(1.0)
    with forward_mode_hint():  # other errors and normal use pass through untouched
        assert float(jax.grad(f)(3.0)) == 6.0
    with pytest.raises(ValueError, match="unrelated"):
        with forward_mode_hint():
            raise ValueError("unrelated")


def test_jacfwd_through_simulate_says_adjoint_forward(paper42):
    def final_x(mu):
        sc = paper42.replace(**{"foundation.friction_coefficient": mu})
        return jh.simulate(
            sc, jh.Times(0.05, n=3), options=jh.SolverOptions(max_steps=10), throw=False
        ).position[-1]

    with pytest.raises(TypeError, match=r"adjoint=diffrax\.ForwardMode\(\)"):
        jax.jacfwd(final_x)(0.3)


# ---- scan and bifurcation parameters, observables, counts


def test_static_fields_are_no_scan_parameters(paper42):
    from jaxhoist._io.validate import check_param_path

    for path in ("t1", "name", "load.mass.real", "load.size[5]"):
        with pytest.raises(jh.ScenarioError, match=re.escape(path.split(".")[0].split("[")[0])):
            check_param_path(paper42, path, "--param")
    check_param_path(paper42, "load.mass_centre[1]", "--param")


def test_strict_numbers():
    from jaxhoist._io.validate import parse_number, parse_values

    assert parse_number(" 1.5e-3 ", "x") == 1.5e-3 and parse_number("-2", "x") == -2.0
    assert np.isnan(parse_number("nan", "x")) and parse_number("-inf", "x") == -np.inf
    for bad in ("0_3", "1_000.0", "0x10", "1e", "", "1,5", "3 4", "½", "１"):
        with pytest.raises(jh.ScenarioError, match="x"):
            parse_number(bad, "x")
    np.testing.assert_array_equal(parse_values("0:1:3", "--values"), [0.0, 0.5, 1.0])
    np.testing.assert_array_equal(parse_values("0.1, 0.2", "--values"), [0.1, 0.2])
    for bad in ("0_1,0.2", "0:1:-3", "0:1:0", "0:1:1_0", "a:b", "0:1:2:3", ""):
        with pytest.raises(jh.ScenarioError, match="--values"):
            parse_values(bad, "--values")


# ---- the command line: exit 2 with one line, before compiling or solving


def _cli(monkeypatch, capsys, argv) -> tuple[int, str]:
    from jaxhoist._apps.cli import app as cli
    from jaxhoist._apps.cli import bifurcation as bifurcation_cli
    from jaxhoist._apps.cli import simulate as simulate_cli

    monkeypatch.setattr(simulate_cli, "_compiled_solve", _core_must_not_run)
    for name in ("scan", "locate_bifurcation", "trace_boundary"):
        monkeypatch.setattr(bifurcation_cli, name, _core_must_not_run)
    capsys.readouterr()
    try:
        code = cli.main(argv)
    except SystemExit as e:  # argparse refusing a flag's value: usage line + one error line, exit 2
        code = e.code
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert "Traceback" not in err
    if code == 2 and lines and lines[-1].startswith("jaxhoist: error:"):
        _one_bounded_line(lines[-1])
    return code, err


@pytest.mark.parametrize(
    "extra,word",
    [
        (["--set", "t1=5"], "--t1"),
        (["--set", "hoist.speed=[0.3,0.3,0.3]"], "hoist.speed"),
        (["--set", "load.mass.real=5"], "load.mass"),
        (["--set", "foundation.friction_coefficient=0_3"], "foundation.friction_coefficient"),
        (["--set", "foundation.stiffness=1e-300"], "foundation.stiffness"),
        (["--t1", "0_5"], "--t1"),
        (["--rtol", "1_0"], "--rtol"),
        (["--n-save", "1_1"], "--n-save"),
    ],
)
def test_cli_simulate_bad_arguments_exit_2(monkeypatch, capsys, tmp_path, extra, word):
    code, err = _cli(
        monkeypatch, capsys, ["simulate", "paper-4.2", "--quiet", "--out", str(tmp_path / "o"), *extra]
    )
    assert code == 2 and word in err, err
    assert not (tmp_path / "o").exists()


def test_cli_scenario_folder_exits_2(monkeypatch, capsys, tmp_path):
    argv = ["simulate", str(tmp_path), "--quiet", "--out", str(tmp_path / "o")]
    code, err = _cli(monkeypatch, capsys, argv)
    assert code == 2 and "folder" in err, err


def test_cli_out_that_is_a_file_or_unwritable_exits_2_before_solving(monkeypatch, capsys, tmp_path):
    f = tmp_path / "file"
    f.write_text("x")
    for out in (f, f / "sub"):
        code, err = _cli(monkeypatch, capsys, ["simulate", "paper-4.2", "--quiet", "--out", str(out)])
        assert code == 2 and "--out" in err and str(f) in err, err
    import os

    if os.geteuid() != 0:  # root writes anywhere
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o500)
        try:
            argv = ["simulate", "paper-4.2", "--quiet", "--out", str(ro / "o")]
            code, err = _cli(monkeypatch, capsys, argv)
            assert code == 2 and "--out" in err and "writable" in err, err
        finally:
            ro.chmod(0o700)


def test_cli_existing_result_folder_needs_overwrite(monkeypatch, capsys, tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    (out / "trajectory.npz").write_bytes(b"old")
    (out / "overview.png").write_bytes(b"old")
    code, err = _cli(monkeypatch, capsys, ["simulate", "paper-4.2", "--quiet", "--out", str(out)])
    assert code == 2 and "--overwrite" in err and str(out) in err, err
    assert (out / "overview.png").read_bytes() == b"old"  # refused: nothing touched
    # with --overwrite, validation passes and the run goes on to compile (trapped here)
    with pytest.raises(AssertionError, match="jitted core"):
        _cli(monkeypatch, capsys, ["simulate", "paper-4.2", "--quiet", "--out", str(out), "--overwrite"])


def test_overwrite_cleans_only_the_files_simulate_writes(tmp_path):
    from jaxhoist._io.validate import clean_outputs

    out = tmp_path / "o"
    out.mkdir()
    for name in ("trajectory.npz", "trajectory.json", "overview.png", "notes.txt", "my.png"):
        (out / name).write_text("old")
    (out / "sub").mkdir()
    removed = clean_outputs(out, ["trajectory.npz", "trajectory.json", "overview.png", "top_view.png"])
    assert sorted(p.name for p in removed) == ["overview.png", "trajectory.json", "trajectory.npz"]
    assert sorted(p.name for p in out.iterdir()) == ["my.png", "notes.txt", "sub"]


def test_failed_run_summary_prints_no_event_times():
    from jaxhoist._apps.cli.app import event_lines, summary_status
    from jaxhoist._errors import SolveStatus

    ts = np.linspace(0.0, 1.0, 11)
    normal = np.full((11, 4), np.inf)
    normal[0] = 1e5
    arrays = {
        "status": np.int32(1),
        "ts": ts,
        "normal_forces": normal,
        "position": np.zeros((11, 3)),
        "energy_residual": np.zeros(11),
    }
    status = summary_status(arrays)
    assert status == SolveStatus.MAX_STEPS
    text = "\n".join(event_lines(status, ts, normal))
    assert not re.search(r"[0-9] s\b", text) and "not available" in text, text
    # a run marked ok whose state or energy residual is non-finite is a failed run
    ok = dict(arrays, status=np.int32(0), normal_forces=np.full((11, 4), 1e5))
    assert summary_status(ok) == SolveStatus.OK
    ok["energy_residual"] = np.full(11, np.nan)
    assert summary_status(ok) == SolveStatus.NONFINITE


@pytest.mark.parametrize(
    "extra,word",
    [
        (["--scan", "-5"], "--scan"),
        (["--scan", "1"], "--scan"),
        (["--observable", "final_position"], "final_position"),
        (["--observable", "detach:Q-D"], "detach:Q-D"),
        (["--observable", "final_posture"], "final_position"),
        (["--param", "t1"], "t1"),
        (["--tol", "1_0"], "--tol"),
        (["--bracket", "0_2", "0.4"], "--bracket"),
    ],
)
def test_cli_bifurcation_bad_arguments_exit_2(monkeypatch, capsys, extra, word):
    code, err = _cli(monkeypatch, capsys, [*BIFURCATION_MU, *extra])
    assert code == 2 and word in err, err


# ---- measurement CSV files (identify)


def _csv(tmp_path, text: str | bytes, name: str = "m.csv"):
    p = tmp_path / name
    p.write_bytes(text if isinstance(text, bytes) else text.encode())
    return p


GOOD_CSV = "t [s],position_x [m]\n0.0,1.0\n0.1,1.5\n0.2,2.0\n"


def test_measurement_bom_header_is_read(tmp_path):
    from jaxhoist._io.measurement import read_measurement

    m = read_measurement(_csv(tmp_path, b"\xef\xbb\xbf" + GOOD_CSV.encode()))
    np.testing.assert_allclose(m.t, [0.0, 0.1, 0.2])


@pytest.mark.parametrize(
    "content,word",
    [
        (GOOD_CSV.replace("1.5", "1_5"), "line 3"),  # underscores: not 15
        (GOOD_CSV.encode("utf-16"), "UTF-16"),
        (GOOD_CSV.encode() + b"0.3,\xe9\n", "UTF-8"),
        (GOOD_CSV.replace("1.5", "1.5\x00"), "NUL"),
        (GOOD_CSV.replace("1.5", "1" + "0" * 400), "position_x"),  # 1e400: not finite
    ],
    ids=["underscore", "utf-16", "latin-1", "nul", "huge"],
)
def test_measurement_bad_bytes_and_numbers(tmp_path, content, word):
    from jaxhoist._io.measurement import MeasurementError, read_measurement

    with pytest.raises(MeasurementError) as info:
        read_measurement(_csv(tmp_path, content))
    msg = _one_bounded_line(str(info.value))
    assert word in msg and "m.csv" in msg, msg


def test_measurement_path_that_is_a_folder(tmp_path):
    from jaxhoist._io.measurement import MeasurementError, read_measurement

    with pytest.raises(MeasurementError, match="folder"):
        read_measurement(tmp_path)


def test_cli_overwrite_replaces_a_previous_run(tmp_path, capsys):
    """End to end (the short solve of tests/test_cli.py, compiled once per process): a second run into the
    folder that simulate wrote replaces its results (with --no-plots the old PNGs are gone, the data is
    new, the user's own file stays); a folder simulate did not write needs --overwrite."""
    from jaxhoist._apps.cli import app as cli
    from jaxhoist._io import results

    out = tmp_path / "o"
    short = ["simulate", "paper-4.2", "--t1", "0.5", "--n-save", "11", "--out", str(out), "--quiet"]
    assert cli.main(short) == 0
    assert list(out.glob("*.png"))
    (out / "notes.txt").write_text("mine")
    mu = ["--set", "foundation.friction_coefficient=0.3"]
    (out / ".jaxhoist").unlink()  # as if written by hand or by another program
    assert cli.main([*short, *mu]) == 2
    assert "--overwrite" in capsys.readouterr().err
    assert cli.main([*short, *mu, "--overwrite", "--no-plots"]) == 0
    assert not list(out.glob("*.png")) and (out / "notes.txt").read_text() == "mine"
    md = results.load_metadata(out / "trajectory.npz")
    assert md["scenario"]["leaves"]["foundation.friction_coefficient"] == 0.3
    assert cli.main([*short, "--no-plots"]) == 0  # marked now: the same command runs again
