"""Adversarial inputs, fuzzed: a mutated scenario file either loads or raises `ScenarioError` with
one line of bounded length, never another exception; `simulate --set PATH=VALUE` either passes validation
(reaching the compile step, trapped here: nothing is solved) or exits 2 with one bounded line on stderr.

Hypothesis runs derandomized (a fixed seed) with few examples, so the file takes seconds."""

import contextlib
import io
from importlib import resources

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import jaxhoist as jh
from jaxhoist._apps.cli import app as cli
from jaxhoist._apps.cli import simulate as simulate_cli
from jaxhoist._errors import MAX_MESSAGE_CHARS

PRESETS = ("paper-2.3", "paper-4.1", "paper-4.2", "paper-4.3")
FUZZ = settings(
    max_examples=60, derandomize=True, deadline=None, suppress_health_check=[HealthCheck.too_slow]
)


def _text(name: str) -> str:
    return resources.files("jaxhoist._io.presets").joinpath(f"{name}.toml").read_text()


TEXTS = {n: _text(n) for n in PRESETS}

# Values a user might type where a number, a 3-vector or a string belongs.
WRONG_VALUES = [
    '"12.5"',
    "true",
    "[]",
    "[1.0, 2.0]",
    "[[1.0, 2.0, 3.0]]",
    "1" + "0" * 400,
    "-1",
    "nan",
    "inf",
    "-inf",
    "{ a = 1 }",
    "1e999",
    "0x10",
    "1_000",
    "0.3_0",
    '"',
    "[1, [2, [3]]]",
    "1e-320",
    "9" * 5000,
    "[" * 2000 + "]" * 2000,
    "[" + "0.3, " * 20000 + "0.3]",
    "1979-05-27",
    "+0.0",
    "-0.0",
    "1e300",
    "1e-300",
]


@st.composite
def mutated_scenario(draw) -> bytes:
    """A preset's text with one to three mutations, encoded in one of several ways."""
    text = TEXTS[draw(st.sampled_from(PRESETS))]
    for _ in range(draw(st.integers(1, 3))):
        lines = text.splitlines() or [""]
        i = draw(st.integers(0, len(lines) - 1))
        kind = draw(st.sampled_from(["delete", "duplicate", "retype", "insert", "truncate", "swap"]))
        if kind == "delete":
            del lines[i]
        elif kind == "duplicate":
            lines.insert(i, lines[i])
        elif kind == "retype" and "=" in lines[i]:
            key = lines[i].split("=", 1)[0]
            lines[i] = f"{key}= {draw(st.sampled_from(WRONG_VALUES))}"
        elif kind == "insert":
            lines.insert(i, draw(st.text(max_size=30)))
        elif kind == "swap":
            j = draw(st.integers(0, len(lines) - 1))
            lines[i], lines[j] = lines[j], lines[i]
        text = "\n".join(lines) + "\n"
        if kind == "truncate":
            text = text[: draw(st.integers(0, len(text)))]
    encoding = draw(st.sampled_from(["utf-8", "utf-8", "utf-8", "utf-8-sig", "utf-16", "latin-1"]))
    data = text.encode(encoding, errors="replace")
    if draw(st.booleans()) and draw(st.booleans()):  # a quarter of the files get random bytes spliced in
        k = draw(st.integers(0, len(data)))
        data = data[:k] + draw(st.binary(min_size=1, max_size=8)) + data[k:]
    return data


@pytest.fixture(scope="module")
def fuzz_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("fuzz")


def _bounded_line(msg: str) -> None:
    assert msg and "\n" not in msg and len(msg) <= MAX_MESSAGE_CHARS, (len(msg), msg[:300])


@FUZZ
@given(data=mutated_scenario())
def test_mutated_scenario_file_loads_or_says_why(fuzz_dir, data):
    path = fuzz_dir / "mutated.toml"
    path.write_bytes(data)
    try:
        sc = jh.load_scenario(path)
    except jh.ScenarioError as e:
        _bounded_line(str(e))
        assert str(path) in str(e), str(e)  # every file error names the file
        return
    sc.check()  # what loads is a valid scenario
    assert sc.t1 > 0 and float(sc.load.mass) > 0


# ---- simulate --set PATH=VALUE, parsed and validated in-process; the compile step is a trap


class _Reached(Exception):
    """Validation passed: the CLI went on to compile."""


def _trap(*args, **kwargs):
    raise _Reached


PATHS = [
    "foundation.friction_coefficient",
    "rope.stiffness",
    "hoist.speed",
    "load.size",
    "load.mass",
    "load.mass_centre",
    "boom.tip_position",
    "boom.stiffness",
    "gravity",
    "rope.attachment",
    "foundation.friction.regularisation_velocity",
    "t1",
    "name",
    "description",
    "load.mass.real",
    "load",
    "foundation.friction",
    "rope.stifness",
    "_private",
    "load..mass",
    "load.mass[0]",
    "",
]
NUMBERS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-(10**400), 10**400).map(str),
    st.sampled_from(
        [
            "0_3",
            "0x10",
            "1e",
            ".5",
            "5.",
            "+1",
            "--1",
            "1,5",
            "١",
            "½",
            "1e999",
            "nan",
            "inf",
            "",
            " ",
            "[",
            "]",
            "[1,",
            "true",
            "null",
            '"0.3"',
        ]
    ),
)
VALUES = st.one_of(
    NUMBERS,
    st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=5).map(lambda v: str(v)),
    st.lists(st.sampled_from(["1", "2.5", "0_1", "true", "[1]", '"a"', "1e400", "9" * 400]), max_size=4).map(
        lambda v: "[" + ", ".join(v) + "]"
    ),
    st.integers(0, 3000).map(lambda n: "[" * n + "]" * n),
    st.text(max_size=20),
)


@FUZZ
@given(
    path=st.one_of(st.sampled_from(PATHS), st.text(max_size=15)),
    value=VALUES,
    sep=st.sampled_from(["=", "=", "=", ":", "=="]),
)
def test_simulate_set_is_validated_or_refused_in_one_line(fuzz_dir, monkeypatch_module, path, value, sep):
    err = io.StringIO()
    argv = [
        "simulate",
        "paper-4.2",
        "--quiet",
        "--out",
        str(fuzz_dir / "never-written"),
        "--set",
        f"{path}{sep}{value}",
    ]
    with contextlib.redirect_stderr(err):
        try:
            code = cli.main(argv)
        except _Reached:
            return  # a valid override: nothing was solved
        except SystemExit as e:  # argparse (a value starting with '-' read as an option): usage + error
            assert e.code == 2
            last = err.getvalue().strip().splitlines()[-1]
            assert last.startswith("jaxhoist simulate: error:"), last
            _bounded_line(last)
            return
    assert code == 2, (code, err.getvalue()[:300])
    lines = [ln for ln in err.getvalue().splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("jaxhoist: error:"), lines[:3]
    _bounded_line(lines[0])
    assert not (fuzz_dir / "never-written").exists()


@pytest.fixture(scope="module")
def monkeypatch_module():
    mp = pytest.MonkeyPatch()
    mp.setattr(simulate_cli, "_compiled_solve", _trap)
    yield mp
    mp.undo()
