"""Shared test set-up: float64, two host CPU devices, session-scoped presets and scenarios.

Compile once, reuse: the fixtures below derive every scenario from the `paper-4.2` preset (so the static
fields `name` and `t1` and the pytree structure are the same) and change leaf *values* only
(`Scenario.replace`, `eqx.tree_at`). Tests that simulate pass `N_SAVE` saved times and the shared
`SOLVE_OPTIONS`, so the jit cache of the solve core hits across tests and test files. Only the friction law
(`RegularisedCoulomb` in the preset, `BristleFriction` in `paper42_bristle`) changes the structure.
"""

import atexit
import os
import shutil
import tempfile

import jax

# One persistent compilation cache for the whole test session, in a temporary folder (never the user's cache
# folder): the process that imports this file first (pytest's controller, or the one process of `-n 0`)
# creates it, empty, and deletes it at exit; the xdist workers and every subprocess (the documented commands
# and scripts of tests/test_docs.py, the CLI, scripts of tests/test_scan.py) inherit it through the
# environment: JAXHOIST_CACHE_DIR for the command line's `main()` (also run in this process by the CLI tests)
# and `jh.enable_compilation_cache()`, JAX's own variables for any process that imports JAX. So a program
# compiled once in the session is loaded, not compiled again, in the next test module (each module drops its
# compiled code, see `_release_compiled_code`), in the other worker, or in a command's second run. Every
# program is stored, the small ones too (as `jh.enable_compilation_cache()` sets it), and the workers switch
# the library's cache on (below), as the command line does: jaxhoist's own programs are stored whole and
# loaded without tracing. The suite starts from an empty cache every time; set JAXHOIST_TEST_CACHE_DIR to a
# folder to keep the cache between sessions instead. tests/test_compilation_cache.py gives its subprocesses
# folders of their own, to test the cold behaviour; tests of in-process tracing and compiling switch the
# library's cache off while they run.
if not os.environ.get("JAXHOIST_TEST_CACHE_DIR"):
    _folder = tempfile.mkdtemp(prefix="jaxhoist-test-cache-")
    atexit.register(shutil.rmtree, _folder, ignore_errors=True)
    os.environ["JAXHOIST_TEST_CACHE_DIR"] = _folder
CACHE_ENV = {
    "JAXHOIST_CACHE_DIR": os.environ["JAXHOIST_TEST_CACHE_DIR"],
    "JAX_COMPILATION_CACHE_DIR": os.environ["JAXHOIST_TEST_CACHE_DIR"],
    "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS": "0",
    "JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES": "-1",
    # The workers run with two CPU devices (below), and so do subprocesses that do not set the count
    # themselves: JAX's own cache key holds the device count (jaxhoist's stored programs' key does not), and
    # a scan chooses its group width from the devices, so a process with another count would compile anew.
    "JAX_NUM_CPU_DEVICES": "2",
}
os.environ.update(CACHE_ENV)
# JAX read its variables when it was imported (a plugin may have imported it before this file): set them here
# too, before the first compilation, which decides once per process whether the cache is used.
jax.config.update("jax_compilation_cache_dir", CACHE_ENV["JAX_COMPILATION_CACHE_DIR"])
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)

# Two CPU devices so that sharding code paths are exercised; this must happen before the backend starts.
try:
    jax.config.update("jax_num_cpu_devices", 2)
except AttributeError:  # older JAX: the XLA flag, read when the backend initialises
    flags = os.environ.get("XLA_FLAGS", "")
    os.environ["XLA_FLAGS"] = (flags + " --xla_force_host_platform_device_count=2").strip()
jax.config.update("jax_enable_x64", True)
# Strict dtype promotion: mixing dtypes (bool or int with float arrays, float32 with float64) is
# an error rather than a silent promotion; Python scalars stay weakly typed. On by default; opt out with
# JAXHOIST_STRICT_PROMOTION=0 (e.g. to tell a promotion error from a numerical one).
STRICT_PROMOTION = os.environ.get("JAXHOIST_STRICT_PROMOTION", "1") != "0"
if STRICT_PROMOTION:
    jax.config.update("jax_numpy_dtype_promotion", "strict")

import tomllib  # noqa: E402
from importlib import resources  # noqa: E402

import diffrax  # noqa: E402
import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import pytest  # noqa: E402

import jaxhoist as jh  # noqa: E402

# The library's cache on, in the session's folder, in every worker: jaxhoist's own programs are stored whole
# (`stored_programs`), so the next module, the other worker and the subprocesses load them without tracing
# (measured: about 5 % of the suite's worker time, most of it tracing).
jh.enable_compilation_cache(CACHE_ENV["JAXHOIST_CACHE_DIR"])
from jaxhoist._numerics import persistent_cache  # noqa: E402

_SESSION_CACHE = persistent_cache.enabled_folder()

PRESETS = ("paper-2.3", "paper-4.1", "paper-4.2", "paper-4.3")

# Every simulate() in the physics tests saves this many times, so one compiled core serves them all
# (ts is an array argument: its values may change, its length may not).
N_SAVE = 201
# Shared solver settings (static arguments of the jitted core: a change recompiles). Tsit5 at rtol 1e-8 keeps
# the solver error well below every physical tolerance asserted with them (the default Rosenbrock-W solver is
# order 3 and meant for loose tolerances; it has tests of its own in test_rosenbrock.py).
SOLVE_OPTIONS = jh.SolverOptions(diffrax.Tsit5(), rtol=1e-8, atol=1e-9)


def run(scenario: jh.Scenario, ts, **kw) -> jh.Trajectory:
    """`simulate` with the shared solver settings on the given saved times (len(ts) should be N_SAVE)."""
    return jh.simulate(scenario, jh.Times(ts=jnp.asarray(ts, dtype=jnp.float64)), options=SOLVE_OPTIONS, **kw)


def with_bristle(scenario: jh.Scenario, **kw) -> jh.Scenario:
    """The same scenario with the bristle friction law (defaults unless given)."""
    return eqx.tree_at(lambda s: s.foundation.friction, scenario, jh.BristleFriction(**kw))


def with_coulomb(scenario: jh.Scenario, eps: float = 1e-3) -> jh.Scenario:
    """The same scenario with the regularised Coulomb law of regularisation velocity `eps` [m/s]."""
    return eqx.tree_at(lambda s: s.foundation.friction, scenario, jh.RegularisedCoulomb(eps))


@pytest.fixture(scope="session")
def preset_dicts() -> dict[str, dict]:
    """The bundled presets as plain TOML dicts (to edit and feed to `scenario_from_dict`)."""
    pkg = resources.files("jaxhoist._io.presets")
    return {n: tomllib.loads(pkg.joinpath(f"{n}.toml").read_text()) for n in PRESETS}


@pytest.fixture(scope="session")
def paper42() -> jh.Scenario:
    """The paper-4.2 preset: 31 875 kg container, offset mass centre, rope at the top corner above D."""
    return jh.load_scenario("paper-4.2")


@pytest.fixture(scope="session")
def paper42_bristle(paper42) -> jh.Scenario:
    """paper-4.2 with the default bristle friction law."""
    return with_bristle(paper42)


@pytest.fixture(scope="session")
def centred42(paper42) -> jh.Scenario:
    """paper-4.2's box with its mass centre at the box centre, rope at the top-face centre straight below the
    boom tip (a vertical lift through C: no tilt, no yaw, no horizontal force by symmetry), hoist stopped."""
    a, b, c = (float(x) for x in paper42.load.size)
    return paper42.replace(
        **{
            "load.mass_centre": [a / 2, b / 2, c / 2],
            "rope.attachment": [a / 2, b / 2, c],
            "boom.tip_position": [a / 2, b / 2, 10.0],
            "hoist.speed": 0.0,
        }
    )


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_code():
    """After each test module, drop the compiled executables that the package and JAX keep for the process's
    life. Each executable holds memory maps of its machine code; the whole suite in one process reached the
    kernel's limit (vm.max_map_count = 65 530; about 24 000 maps a third of the way through) and XLA's next
    compile died with a segmentation fault (tests/test_statics.py, after ~250 tests). Within a module the
    compiled functions are still shared."""
    yield
    from jaxhoist._numerics import batch, compile_cache

    compile_cache.clear()  # the bifurcation locator's solves and the rigid model's pieces among them
    batch.chunk_fn.cache_clear()
    jax.clear_caches()
    # a test may have switched the library's cache off or moved it: the next module starts with the session's
    persistent_cache._ENABLED[0] = _SESSION_CACHE


def pytest_collection_modifyitems(config, items):
    """The documented pages of tests/test_docs.py first: with `--no-loadscope-reorder` (pyproject.toml's
    addopts) pytest-xdist hands out the units of work in this order, and the pages are the longest units, so
    the two workers finish together rather than one waiting on a long unit handed out last."""
    items.sort(key=lambda item: item.path.name != "test_docs.py")  # stable: the order within a file is kept


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """`--dist loadfile` with each page of tests/test_docs.py a unit of its own: every other test file runs
    whole in one worker (its module fixtures and compiled functions shared), while the documented pages
    (minutes each, the blocks of a page sharing a folder) spread over both workers instead of holding one of
    them for most of the run. Other `--dist` modes are left to pytest-xdist."""
    if config.getvalue("dist") != "loadfile":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class FileOrPageScheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            file, _, rest = nodeid.partition("::")
            if file.endswith("test_docs.py") and "[" in rest:
                return (
                    file + "::" + rest.split("[", 1)[1].rsplit(":", 1)[0]
                )  # the page, from the id PAGE:LINE
            return file

    return FileOrPageScheduling(config, log)


# Shared by several test files: the stiff member and its capped Tsit5 solve (one compiled program)
#: Tsit5 with a step budget of 10 000: `stiff_member` over 1 s needs about 13 000 steps of it, so it stops at
#: the budget (test_rosenbrock.py's stiff member, test_transforms.py's max_steps test: one compiled program).
TSIT5_CAPPED = jh.SolverOptions(diffrax.Tsit5(), max_steps=10_000)


def stiff_member(scenario: jh.Scenario) -> jh.Scenario:
    """`scenario` with ε = 1e-5 m/s and k = 1.5e9 N/m: friction slope and foundation 100x stiffer than
    paper-4.2's (the same pytree structure)."""
    stiff = scenario.replace(**{"foundation.stiffness": 1.5e9})
    return eqx.tree_at(lambda s: s.foundation.friction, stiff, jh.RegularisedCoulomb(1e-5))
