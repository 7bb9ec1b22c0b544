"""Adversarial inputs: how each class of bad input ends.

Runs every case in-process with the compile and solve steps replaced by traps (nothing is solved), and
prints, per class of input, how many cases ended in

- `clear`: a `ScenarioError` (exit 2 from the CLI, argparse's exit 2 for a flag) of one line <= 600 chars;
- `unclear`: such an error, but longer than 600 characters or on several lines;
- `traceback`: any other exception, or the wrong exit code (1 is reserved for solver failures);
- `silent`: a known-bad input accepted (validation passed: the trapped compile/solve step was reached);
- `valid ok` / `valid refused`: inputs that are fine (a UTF-8 BOM, a mutation that leaves a valid file);
  a mutated file that still loads counts as `valid ok`.

    PYTHONPATH=$PWD python experiments/figures/adversarial_inputs.py            # about 20-40 s on one core
    PYTHONPATH=$PWD python experiments/figures/adversarial_inputs.py --quick    # fewer mutated files
    PYTHONPATH=/path/to/old/checkout python experiments/figures/adversarial_inputs.py   # the "before" figures

Its cases go through public entry points (`load_scenario`, `Scenario.replace`, `simulate`, the command
line's `main`, `read_measurement`); the traps replace internal compile and solve functions (`_install_traps`,
internal on purpose).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import random
import sys
import tempfile
import time
from collections import Counter, defaultdict
from importlib import resources
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxhoist as jh  # noqa: E402

LIMIT = 600  # characters of an error line


class Reached(Exception):
    """The trapped compile or solve step: validation let the input through."""


def _trap(*args, **kwargs):
    raise Reached


def _install_traps():
    # internal on purpose: traps the compile/solve entry points, to see what validation lets through
    import jaxhoist._apps.scan.run as scan_mod  # internal: trapped
    import jaxhoist._numerics.solve as solve_mod  # internal: trapped
    from jaxhoist._apps.cli import bifurcation as bifurcation_cli  # internal: trapped
    from jaxhoist._apps.cli import simulate as simulate_cli  # internal: trapped

    simulate_cli._compiled_solve = _trap
    solve_mod._solve_jit = _trap
    scan_mod._fingerprint = _trap  # scan(): called after every host-side check, before compiling
    for name in ("scan", "locate_bifurcation", "trace_boundary"):
        setattr(bifurcation_cli, name, _trap)
    import jaxhoist._numerics.rigid.solve as rigid  # internal: trapped

    rigid.simulate_rigid = _trap


def _classify_error(msg: str) -> str:
    return "clear" if msg and "\n" not in msg.strip() and len(msg.strip()) <= LIMIT else "unclear"


def run_py(fn) -> str:
    """Outcome of a Python call: 'accepted', 'reached', 'clear', 'unclear' or 'traceback'."""
    try:
        fn()
    except Reached:
        return "reached"
    except jh.ScenarioError as e:
        return _classify_error(str(e))
    except TypeError as e:
        return "clear" if "adjoint=diffrax.ForwardMode()" in str(e) else "traceback"
    except Exception:
        return "traceback"
    return "accepted"


def run_cli(argv) -> str:
    from jaxhoist._apps.cli import app as cli  # internal: the command line's main, run in-process

    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            code = cli.main(list(argv))
        except Reached:
            return "reached"
        except SystemExit as e:  # argparse: usage line + one error line, exit 2
            lines = [ln for ln in err.getvalue().splitlines() if ln.strip() and not ln.startswith("usage")]
            return _classify_error(lines[-1]) if e.code == 2 and lines else "traceback"
        except Exception:
            return "traceback"
    lines = [ln for ln in err.getvalue().splitlines() if ln.strip()]
    if code == 2 and lines:
        return _classify_error(lines[-1]) if len(lines) == 1 else "unclear"
    return "traceback" if code != 0 else "accepted"


# ------------------------------------------------------------------------------------------- cases


def preset(name="paper-4.2") -> str:
    return resources.files("jaxhoist._io.presets").joinpath(f"{name}.toml").read_text()


def file_cases(tmp: Path, n_mutations: int):
    """(label, path, known bad?) for scenario files."""
    base = preset()
    out = []

    def add(label, data, bad=True):
        p = tmp / f"{len(out):04d}.toml"
        p.write_bytes(data if isinstance(data, bytes) else data.encode())
        out.append((label, p, bad))

    add("integer 1e400 (t1)", base.replace("t1 = 25.0", "t1 = 1" + "0" * 400))
    add("integer 9e329 (tip_mass)", base.replace("tip_mass = 500.0", "tip_mass = " + "9" * 330))
    add("integer in a vector", base.replace("size = [2.5, 6.0", "size = [2.5, 1" + "0" * 320))
    add("integer of 5000 digits", base.replace("speed = 0.3", "speed = " + "7" * 5000))
    add("Latin-1 file", base.replace("our choice", "ça").encode("latin-1", errors="replace"))
    add("UTF-16 file", base.encode("utf-16"))
    add("invalid UTF-8 byte", base.encode() + b"\n# \xff\xfe\n")
    add("array nested 100000 deep", base + "\nx = " + "[" * 100_000 + "]" * 100_000 + "\n")
    huge = "speed = [" + ", ".join(["0.3"] * 2_000_000) + "]"
    add("2-million-element array", base.replace("speed = 0.3", huge))
    add("density 1e300", base.replace("density = 850.0", "density = 1e300"))
    add("foundation stiffness 1e-300", base.replace("stiffness = 1.5e7", "stiffness = 1e-300"))
    add("negative mu (control)", base.replace("friction_coefficient = 0.25", "friction_coefficient = -0.25"))
    add("UTF-8 with BOM (valid)", b"\xef\xbb\xbf" + base.encode(), bad=False)
    folder = tmp / "a-folder.toml"
    folder.mkdir()
    out.append(("path is a folder", folder, True))
    # mutated presets (a fixed seed): delete / duplicate / retype / swap lines, truncate, splice bytes,
    # re-encode; whether each is bad is not known in advance
    rng = random.Random(14)
    wrong = [
        '"12.5"',
        "true",
        "[]",
        "[1.0, 2.0]",
        "1" + "0" * 400,
        "-1",
        "nan",
        "inf",
        "{ a = 1 }",
        "1e999",
        "0x10",
        "1_000",
        "[" * 2000 + "]" * 2000,
        "1e-300",
        "1e300",
        "9" * 5000,
    ]
    texts = [preset(n) for n in ("paper-2.3", "paper-4.1", "paper-4.2")]
    for k in range(n_mutations):
        lines = rng.choice(texts).splitlines()
        i = rng.randrange(len(lines))
        kind = rng.choice(["delete", "duplicate", "retype", "retype", "swap", "truncate", "bytes", "encode"])
        if kind == "delete":
            del lines[i]
        elif kind == "duplicate":
            lines.insert(i, lines[i])
        elif kind == "retype" and "=" in lines[i]:
            lines[i] = lines[i].split("=", 1)[0] + "= " + rng.choice(wrong)
        elif kind == "swap":
            j = rng.randrange(len(lines))
            lines[i], lines[j] = lines[j], lines[i]
        text = "\n".join(lines) + "\n"
        data = text.encode()
        if kind == "truncate":
            data = data[: rng.randrange(len(data))]
        elif kind == "bytes":
            j = rng.randrange(len(data))
            data = data[:j] + bytes(rng.randrange(256) for _ in range(rng.randint(1, 6))) + data[j:]
        elif kind == "encode":
            data = text.encode(rng.choice(["utf-16", "latin-1", "utf-16-le", "cp1252"]), errors="replace")
        add(f"mutation {k} ({kind})", data, bad=None)
    return out


def cli_cases(tmp: Path):
    """(class, label, argv, known bad?) for command lines."""
    f = tmp / "a-file"
    f.write_text("x")
    full = tmp / "full"
    full.mkdir()
    (full / "overview.png").write_text("old")
    ro = tmp / "read-only"
    ro.mkdir()
    ro.chmod(0o500)
    o = str(tmp / "never")
    sim = ["simulate", "paper-4.2", "--quiet", "--no-plots"]
    deep = "[" * 5000 + "]" * 5000
    cases = [
        ("--set t1=5", [*sim, "--out", o, "--set", "t1=5"]),
        ("--set hoist.speed=[0.3,0.3,0.3]", [*sim, "--out", o, "--set", "hoist.speed=[0.3,0.3,0.3]"]),
        ("--set load.mass.real=5", [*sim, "--out", o, "--set", "load.mass.real=5"]),
        ("--set mu=0_3", [*sim, "--out", o, "--set", "foundation.friction_coefficient=0_3"]),
        ("--set mu=-0.1 (control)", [*sim, "--out", o, "--set", "foundation.friction_coefficient=-0.1"]),
        ("--set foundation.stiffness=1e-300", [*sim, "--out", o, "--set", "foundation.stiffness=1e-300"]),
        ("--set load.mass=1e300", [*sim, "--out", o, "--set", "load.mass=1e300"]),
        ("--set hoist.speed=<5000-deep list>", [*sim, "--out", o, "--set", f"hoist.speed={deep}"]),
        ("--set load.size=<1e400 in a list>", [*sim, "--out", o, "--set", f"load.size=[1, 1{'0' * 400}, 1]"]),
        ("--t1 0_5", [*sim, "--out", o, "--t1", "0_5"]),
        ("--out is a file", [*sim, "--out", str(f)]),
        ("--out below a file", [*sim, "--out", str(f / "sub")]),
        ("--out non-empty, no --overwrite", [*sim, "--out", str(full)]),
        ("scenario path is a folder", ["simulate", str(tmp), "--quiet", "--out", o]),
        ("scan --param t1", ["scan", "paper-4.2", "--param", "t1", "--values", "1,2", "--out", o]),
        ("scan --param load.mass.real", ["scan", "paper-4.2", "--param", "load.mass.real", "--values", "1"]),
        (
            "scan --values 0_1,0.2",
            [
                "scan",
                "paper-4.2",
                "--param",
                "foundation.friction_coefficient",
                "--values",
                "0_1,0.2",
                "--out",
                o,
            ],
        ),
    ]
    if os.geteuid() != 0:
        cases.append(("--out in a read-only folder", [*sim, "--out", str(ro / "o")]))
    bif = ["bifurcation", "paper-4.2", "--param", "foundation.friction_coefficient"]
    bif += ["--bracket", "0.2", "0.4"]
    cases += [
        ("bifurcation --scan -5", [*bif, "--scan", "-5"]),
        ("bifurcation --observable final_position", [*bif, "--observable", "final_position"]),
        ("bifurcation --observable detach:Q-D", [*bif, "--observable", "detach:Q-D"]),
        ("bifurcation --param t1", [*bif[:3], "t1", *bif[4:]]),
        ("bifurcation --tol 1_0", [*bif, "--tol", "1_0"]),
    ]
    out = [("simulate/scan/bifurcation args", label, argv, True) for label, argv in cases]
    out.append(
        (
            "simulate/scan/bifurcation args",
            "valid --set (control)",
            [*sim, "--out", o, "--set", "foundation.friction_coefficient=0.3"],
            False,
        )
    )
    return out


def api_cases(paper42):
    mu = "foundation.friction_coefficient"

    def sim(leaves):
        return jh.simulate(paper42.replace(**leaves), 0.1)

    def jacfwd():
        def f(x):
            sc = paper42.replace(**{mu: x})
            return jh.simulate(
                sc, jh.Times(0.05, n=3), options=jh.SolverOptions(max_steps=10), throw=False
            ).position[-1]

        import jaxhoist._numerics.solve as solve_mod  # internal: its trap undone, tracing only

        saved = solve_mod._solve_jit
        solve_mod._solve_jit = solve_mod.eqx.filter_jit(solve_mod.solve)  # tracing only: fails before solving
        try:
            jax.jacfwd(f)(0.3)
        finally:
            solve_mod._solve_jit = saved

    cases = [
        ("simulate, mu < 0", lambda: sim({mu: -0.1}), True),
        ("replace typo", lambda: paper42.replace(**{"foundation.friction_coeficient": 0.3}), True),
        ("replace typo in a table", lambda: paper42.replace(**{"fundation.stiffness": 1e7}), True),
        ("replace vector into a scalar", lambda: sim({"hoist.speed": [0.3] * 3}), True),
        ("replace with text", lambda: sim({"rope.stiffness": "stiff"}), True),
        ("replace t1", lambda: paper42.replace(**{"t1": 5.0}), True),
        ("simulate, stiffness 1e-300", lambda: sim({"foundation.stiffness": 1e-300}), True),
        ("simulate, mass 1e300", lambda: sim({"load.mass": 1e300}), True),
        (
            "simulate(t1=1, ts ending at 0.05)",
            lambda: jh.simulate(paper42, jh.Times(1.0, ts=np.array([0, 0.02, 0.05]))),
            True,
        ),
        ("jacfwd through the default adjoint", jacfwd, True),
        ("valid replace + simulate (control)", lambda: jh.simulate(paper42.replace(**{mu: 0.3}), 0.1), False),
    ]
    return [("Python API", label, fn, bad) for label, fn, bad in cases]


def csv_cases(tmp: Path):
    read_measurement = jh.read_measurement

    good = "t [s],position_x [m]\n0.0,1.0\n0.1,1.5\n0.2,2.0\n"
    items = [
        ("BOM in the header (valid)", b"\xef\xbb\xbf" + good.encode(), False),
        ("cell 1_5", good.replace("1.5", "1_5").encode(), True),
        ("UTF-16 file", good.encode("utf-16"), True),
        ("Latin-1 byte", good.encode() + b"0.3,\xe9\n", True),
        ("NUL byte", good.replace("1.5", "1.5\x00").encode(), True),
        ("cell 1e400", good.replace("1.5", "1" + "0" * 400).encode(), True),
    ]
    out = []
    for k, (label, data, bad) in enumerate(items):
        p = tmp / f"m{k}.csv"
        p.write_bytes(data)
        out.append(("measurement CSV", label, (lambda p=p: read_measurement(p)), bad))
    out.append(("measurement CSV", "path is a folder", (lambda: read_measurement(tmp)), True))
    return out


# ------------------------------------------------------------------------------------------------ run


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="60 mutated files instead of 300")
    ap.add_argument("--out", default=None, help="also write the table to OUT/adversarial_inputs.txt")
    ap.add_argument("--verbose", action="store_true", help="print every known-bad case not ending clearly")
    args = ap.parse_args(argv)
    _install_traps()
    paper42 = jh.load_scenario("paper-4.2")
    t0 = time.perf_counter()
    rows: dict[str, Counter] = defaultdict(Counter)
    notes = []
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        for label, path, bad in file_cases(tmp, 60 if args.quick else 300):
            outcome = run_py(lambda path=path: jh.load_scenario(path))
            cls = "scenario files (named)" if bad is not None else "scenario files (mutated)"
            rows[cls][_tally(outcome, bad)] += 1
            if bad and outcome not in ("clear",):
                notes.append(f"{cls}: {label}: {outcome}")
        cases = cli_cases(tmp)
        for cls, label, a, bad in cases:
            outcome = run_cli(a)
            rows[cls][_tally(outcome, bad)] += 1
            if bad and outcome != "clear":
                notes.append(f"{cls}: {label}: {outcome}")
        for cls, label, fn, bad in [*api_cases(paper42), *csv_cases(tmp)]:
            outcome = run_py(fn)
            rows[cls][_tally(outcome, bad)] += 1
            if bad and outcome != "clear":
                notes.append(f"{cls}: {label}: {outcome}")
        (tmp / "read-only").chmod(0o700) if (tmp / "read-only").exists() else None
    cols = ["cases", "clear", "unclear", "traceback", "silent", "valid ok", "valid refused"]
    lines = [f"{'class of input':34s}" + "".join(f"{c:>14s}" for c in cols)]
    total = Counter()
    for cls, c in rows.items():
        c["cases"] = sum(v for k, v in c.items() if k != "cases")
        total.update(c)
        lines.append(f"{cls:34s}" + "".join(f"{c[k]:14d}" for k in cols))
    lines.append(f"{'all':34s}" + "".join(f"{total[k]:14d}" for k in cols))
    lines.append(f"({time.perf_counter() - t0:.1f} s, jaxhoist from {Path(jh.__file__).parent})")
    text = "\n".join(lines)
    print(text)
    if args.verbose and notes:
        print("\nknown-bad cases not ending in a clear error:\n  " + "\n  ".join(notes))
    if args.out:
        Path(args.out).mkdir(parents=True, exist_ok=True)
        (Path(args.out) / "adversarial_inputs.txt").write_text(text + "\n\n" + "\n".join(notes) + "\n")
    return 0


def _tally(outcome: str, bad) -> str:
    if outcome in ("clear", "unclear", "traceback"):
        return "valid refused" if bad is False and outcome != "traceback" else outcome
    # accepted, or the trapped compile/solve was reached
    return "silent" if bad else "valid ok"


if __name__ == "__main__":
    sys.exit(main())
