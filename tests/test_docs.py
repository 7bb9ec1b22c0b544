"""Every shell and Python block of README.md and docs/ runs, as a reader would run it, and every shell
command runs twice in a row (a documented command must work again on its own output).

Blocks are read with pytest-codeblocks' parser, so its markers apply: `<!--pytest.mark.skip(reason="...")-->`
before a block skips it, `<!--pytest-codeblocks:cont-->` joins a block to the one before. A block too long for
CI carries `<!--pytest.mark.twin("NAME")-->`: the test runs `TWINS["NAME"]` instead, a shortened twin of the
same calls (shorter horizon, fewer members), and fails if the twin is missing.

Each block runs in a fresh process (a Python block with `python -c`, so that it must enable float64 itself,
as a reader's script must), in a working folder of its own page: the blocks of one page share their files, in
page order, as a reader who follows the page does. The folder links `experiments/` and `jaxhoist/` of this
checkout and `.venv/` to the environment running the tests, so commands that name them work; nothing is
written into the checkout.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
from pytest_codeblocks.main import CodeBlock, extract_from_file

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
RUNNABLE = {"python", "sh", "bash"}
#: The wall-clock limit of one run of one block [s].
TIMEOUT = 600

#: Shortened twins of the blocks marked `twin(NAME)`: the same calls on a shorter horizon or fewer members.
TWINS: dict[str, str] = {
    # The set-up is the environment the tests run in; the run command as written after it.
    "readme-run": ".venv/bin/jaxhoist simulate paper-4.2 --out out/paper-4.2\n",
    # 64 values of μ instead of 4000, the first candidate only: the same calls and horizon.
    "bifurcation-scan-locate": """\
import jax

jax.config.update("jax_enable_x64", True)
import numpy as np
import jaxhoist as jh

sc = jh.load_scenario("paper-4.2")
res = jh.scan(
    sc,
    {"foundation.friction_coefficient": np.linspace(0.1, 0.6, 64)},
    jh.Times(25.0, n=2501),
    observables=["final_psi", "liftoff_time", "impacts"],
    out_dir="out/mu",
    progress=True,
)
for j in jh.find_jumps(res, "liftoff_time")[:1]:
    b = jh.locate_bifurcation(
        sc,
        j.param,
        "liftoff_time",
        (j.lo, j.hi),
        times=jh.Times(25.0, n=2501),
        search=jh.SearchOptions(jh.Bisection(), tol=1e-6),
    )
    print(b.summary())
""",
    # The page fits the measurement of docs/cli-analysis.md's identify example (made here first), as written.
    "identify-five": """\
import jax

jax.config.update("jax_enable_x64", True)
import numpy as np
import jaxhoist as jh

m = jh.synthetic_measurement(
    jh.load_scenario("paper-4.2"),
    np.arange(0.02, 5.0, 0.02),
    ["position", "rope_tension"],
    noise={"position": 0.005, "rope_tension": "1%"},
)
jh.write_measurement("lift.csv", m)
res = jh.identify(
    "paper-4.2",
    "lift.csv",
    ["mu", "k", "h", "c_l", "b_l"],
    start={"mu": 0.3},
    noise={"position": 0.005, "rope_tension": "1%"},
)
print(res.summary())
""",
    # The box of docs/lift-planning.md's example as the scenario file the command reads (tests/data holds
    # it), and the command with 16 samples instead of 64.
    "risk-drag-box": f"cp {shlex.quote(str(ROOT / 'tests' / 'data' / 'drag_box.toml'))} drag-box.toml\n"
    + """\
jaxhoist risk drag-box.toml --uncertain "foundation.friction_coefficient=uniform(0.2,0.4)" \
    --uncertain "load.mass_centre[0]=truncnormal(1.0,0.05,0.8,1.2)" --design "boom.tip_position[0]=1:2:3" \
    --hazard slide=0.25 --hazard tilt=3deg --hazard strike --hazard "late:last_contact_time>2.5" \
    --samples 16 --t1 3 --n-save 151 --out out/risk
""",
    # Simulated and animated over 1 s instead of 6 s: 20 frames instead of 120, D's detachment at 0.12 s
    # among them.
    "cli-animate": "jaxhoist simulate paper-4.2 --t1 1 --out out/anim --animate\n",
    # The same optimisation with the check sample and group width of tests/test_optimise.py (a check of 32
    # samples in 4 replicates instead of 64 in 8; 16 members in one group of 16, the example's own width), so
    # that the twin and that test share one compiled scan with derivatives and one without.
    "optimise-drag-box": """\
import jax

jax.config.update("jax_enable_x64", True)
import jaxhoist as jh

box = jh.Scenario(
    load=jh.Load([2.0, 2.0, 0.5], 1000.0),
    foundation=jh.Foundation(1.5e7, 2.0e5, 0.3, jh.RegularisedCoulomb(1e-3)),
    rope=jh.Rope(3e4, 3e3, [1.0, 1.0, 0.5]),
    hoist=jh.ConstantSpeedHoist(0.3),
    boom=jh.Boom([1.6, 1.0, 8.5], 500.0, 5.0e6, 5.0e3),
    name="drag-box",
    t1=3.0,
)
uncertain = {
    "foundation.friction_coefficient": jh.Uniform(0.2, 0.4),
    "load.mass_centre[0]": jh.Normal(1.0, 0.05),
}
res = jh.optimise_lift(
    box,
    uncertain,
    {"max_rope_tension": 1 / 9810.0, "max_tilt": 1.0, "hoist_time": 0.1},
    {"boom.tip_position[0]": (1.0, 1.6), "hoist.speed": (0.2, 0.5)},
    hazard_limits={jh.slide(0.25): 0.5, jh.tilt(degrees=20.0): 0.5},
    hoist_distance=1.0,
    samples=16,
    times=jh.Times(3.0, n=301),
    check_samples=32,
    check_replicates=4,
    batch=jh.BatchOptions(lanes=16, chunk_size=64),
)
print(res.summary())
""",
    # The phases of the first 10 s instead of 70 s, with 101 saved times: the programs of the --quick runs of
    # paper-4.1 in "rigid-sweep" and "rigid-convergence" below, which it loads.
    "rigid-model-phases": """\
import jax

jax.config.update("jax_enable_x64", True)
import jaxhoist

sc = jaxhoist.load_scenario("paper-4.1")
tr = jaxhoist.simulate_rigid(sc, jaxhoist.Times(10.0, n=101))
print(tr.phase_log())
jaxhoist.first_failure(sc, [3.0, 4.0, 7.5])
""",
    # The full runs take minutes to hours: their --quick lines.
    "rigid-convergence": (
        "python experiments/figures/rigid_convergence.py --out out/rigid_convergence --quick\n"
    ),
    "rigid-sweep": "python experiments/figures/rigid_sweep.py --out out/rigid_sweep --quick\n",
}


def _blocks() -> list:
    params = []
    for page in PAGES:
        rel = page.relative_to(ROOT).as_posix()
        for block in extract_from_file(page):
            if block.syntax not in RUNNABLE:
                continue
            marks = [eval(m, {"pytest": pytest, "sys": sys}) for m in block.marks]
            # the id starts with the page: tests/conftest.py makes each page one unit of work for pytest-xdist
            params.append(pytest.param(rel, block, marks=marks, id=f"{rel}:{block.lineno}"))
    return params


@pytest.fixture(scope="module")
def page_dirs(tmp_path_factory) -> dict[str, Path]:
    return {}


@pytest.fixture(scope="module")
def environment(tmp_path_factory) -> dict[str, str]:
    env = dict(os.environ)
    env["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), env.get("PATH", "")])
    env["MPLBACKEND"] = "Agg"
    # JAXHOIST_CACHE_DIR: the session's compilation cache (tests/conftest.py), so a command's second run
    # loads what its first compiled
    env.pop("PYTEST_CURRENT_TEST", None)
    return env


def _workdir(page: str, page_dirs: dict[str, Path], tmp_path_factory) -> Path:
    if page not in page_dirs:
        d = tmp_path_factory.mktemp(page.replace("/", "-").removesuffix(".md"))
        for name in ("experiments", "jaxhoist"):
            (d / name).symlink_to(ROOT / name, target_is_directory=True)
        # `.venv/bin/jaxhoist ...` as the pages write it: the environment running the tests.
        (d / ".venv").symlink_to(Path(sys.executable).parent.parent, target_is_directory=True)
        page_dirs[page] = d
    return page_dirs[page]


def _run(syntax: str, code: str, cwd: Path, env: dict[str, str]) -> subprocess.CompletedProcess:
    if syntax == "python":
        cmd = [sys.executable, "-c", code]
    else:
        cmd = ["bash", "-euo", "pipefail", "-c", code]
    return subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=TIMEOUT)


@pytest.mark.parametrize("page, block", _blocks())
def test_documented_block_runs(
    page: str, block: CodeBlock, request, page_dirs, environment, tmp_path_factory
):
    code = block.code
    twin = request.node.get_closest_marker("twin")
    if twin is not None:
        name = twin.args[0]
        assert name in TWINS, f"{page}:{block.lineno} names twin {name!r}, which tests/test_docs.py lacks"
        code = TWINS[name]
    cwd = _workdir(page, page_dirs, tmp_path_factory)
    runs = 1 if block.syntax == "python" else 2  # a documented command must also run again
    for attempt in range(runs):
        proc = _run(block.syntax, code, cwd, environment)
        assert proc.returncode == 0, (
            f"{page}:{block.lineno} (run {attempt + 1} of {runs}) exited {proc.returncode}\n"
            f"--- code\n{code}--- stdout\n{proc.stdout[-3000:]}\n--- stderr\n{proc.stderr[-3000:]}"
        )


def _nav_pages() -> list[Path]:
    """The pages named in mkdocs.yml's `nav` (read line by line: the test environment has no YAML reader)."""
    text = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    nav = text[text.index("\nnav:") :]
    return [ROOT / "docs" / m for m in re.findall(r"^\s*- (?:[^\n]*?: )?(\S+\.(?:md|ipynb))\s*$", nav, re.M)]


def test_navigation_reaches_every_public_name_and_command():
    """A reader finds every public function and class (of `jaxhoist`, `jaxhoist.plots` and
    `jaxhoist.observables`) in a `:::` directive of a page in the navigation, and every command of the CLI
    as a `## <command>` section of a navigation page."""
    import types

    import jaxhoist as jh
    from jaxhoist._apps.cli.app import build_parser

    pages = _nav_pages()
    assert ROOT / "docs" / "api" / "scans.md" in pages, pages
    text = "\n".join(p.read_text(encoding="utf-8") for p in pages if p.suffix == ".md")
    directives = set(re.findall(r"^:::\s*(\S+)", text, re.M))

    def resolve(dotted: str):
        obj = jh
        for part in dotted.split(".")[1:]:
            obj = getattr(obj, part)
        return obj

    documented = {id(resolve(d)) for d in directives}
    missing = [
        f"jaxhoist.{n}"
        for n in dir(jh)
        if not n.startswith("_")
        and not isinstance(getattr(jh, n), types.ModuleType)  # the two modules: their members below
        and id(getattr(jh, n)) not in documented
    ]
    for mod in (jh.plots, jh.observables):
        for n in dir(mod):
            obj = getattr(mod, n)
            if n.startswith("_") or isinstance(obj, types.ModuleType) or not callable(obj):
                continue
            if getattr(obj, "__module__", "").startswith("jaxhoist") and id(obj) not in documented:
                missing.append(f"{mod.__name__}.{n}")
    assert not missing, f"public names in no API page of the navigation: {missing}"

    sub = next(a for a in build_parser()._actions if a.__class__.__name__ == "_SubParsersAction")
    headings = set(re.findall(r"^## (\S+)\s*$", text, re.M))
    assert set(sub.choices) - headings == set(), f"commands without a section: {set(sub.choices) - headings}"
