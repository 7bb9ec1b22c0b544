"""Moving code between modules changes no result: short-horizon solves of the three presets with both
models, and a 64-member scan with forward-mode sensitivities, equal bit for bit what the code gave when
`tests/data/reference_results.npz` was recorded (by `tests/data/make_reference.py`).

The comparison is exact (`assert_array_equal`, NaN equal to NaN): a move changes where code lives, not the
arithmetic. Should a later change alter only the order of a summation, loosen to 1e-14 relative for the
arrays concerned and say why here and in the commit message. The scan runs on one device, as the reference
did, so the comparison does not depend on how a scan is spread over devices.

Re-recorded on purpose, each time with the differences listed in the commit message (git history keeps
them): the nine `paper-4.2/rigid/*` arrays when the rigid model gained sustained contact cycles through a
compliant phase and persistent contact after impacts (up to 7.7e-7 m and 1.7 N, 748 accepted steps instead
of 928), and the elastic preset arrays, which the default Rosenbrock-W solver computes, whenever its steps
changed on purpose: the cheaper W step, the corner velocities turning with the body in W, the cubic dense
output, the band-entry friction slope (<= 2.9e-5 m over 2 s), the W solve without the 9x18
right-hand-side map (rounding; <= 5.5e-6 m), the stages' ∂f/∂t term with a PI controller at rtol 5e-4 by
default (<= 4.2e-5 m, 2.0e-5 rad, 169 N of normal force and 54 N of rope tension over 2 s; paper-4.2 in 206
accepted steps instead of 274, paper-4.1 105 instead of 97, paper-2.3 178 instead of 164: rtol halved).
Everything once, when jaxhoist began compiling its programs without XLA's CPU fusion emitters
(`jaxhoist._numerics.xla_options`), which round some fused operations differently: the elastic arrays by
<= 2.9e-8 m and 0.89 N over 2 s, the rigid paper-4.2 run in 721 accepted steps instead of 748 (<= 4.1e-8 m),
the scan's values by <= 2.3e-7 and its sensitivities by up to 0.079 per unit of μ (members near a contact
switch, as between two kinds of machine).

XLA compiles for the host CPU's vector instructions, so another kind of machine rounds differently and the
adaptive solvers take other steps from there (`tests/data/make_reference.py` gives the sizes). Each kind of
machine is compared bit for bit with its own recording, `reference_results.<machine>.npz` where one exists
(`make_reference.machine()`), else with `reference_results.npz`, and only where the file was recorded with
the compiler options of this process (`make_reference.STAMP`; the test is skipped, saying so, where they
differ). Recorded so far: the Intel Xeon of the development machine (`reference_results.npz`, with the
present options) and an AMD EPYC with AVX2 and no AVX-512 (`reference_results.x86_64-AuthenticAMD-avx2.npz`,
with XLA's default options and the code before them: on such a machine the test is skipped until it is
recorded again there).
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from jaxhoist._numerics import xla_options

DATA = Path(__file__).parent / "data"


def _make_reference():
    spec = importlib.util.spec_from_file_location("make_reference", DATA / "make_reference.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def mk():
    return _make_reference()


@pytest.fixture(scope="module")
def reference(mk) -> dict[str, np.ndarray]:
    path = mk.reference_path()
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    recorded, now = mk.stamp(arrays), xla_options.describe()
    if recorded != now:  # other compiler options round differently: not comparable bit for bit
        pytest.skip(
            f"{path.name} was recorded with {recorded}, this process compiles with {now}: record this "
            "kind of machine again with `python tests/data/make_reference.py --this-machine`"
        )
    arrays.pop(mk.STAMP, None)
    return arrays


#: Arrays compared to a relative tolerance instead of bit for bit, and why: the scan's sensitivities of one
#: swept parameter are one `jax.jvp` rather than `jax.jacfwd` (a batch of one tangent), a differently
#: compiled program that rounds differently: measured up to 2.3e-14 relative (d_final_psi), 1.8e-14
#: (d_final_position), 2.3e-15 (d_max_tilt); the values, status and steps stay bit for bit.
RTOL = {"scan/d_": 1e-13}


def _compare(got: dict[str, np.ndarray], want: dict[str, np.ndarray], prefix: str) -> None:
    want = {k: v for k, v in want.items() if k.startswith(prefix)}
    assert sorted(got) == sorted(want)
    for k, v in want.items():
        assert got[k].dtype == v.dtype, k
        rtol = next((r for p, r in RTOL.items() if k.startswith(p)), None)
        if rtol is None:
            np.testing.assert_array_equal(got[k], v, err_msg=k, strict=True)
        else:
            np.testing.assert_allclose(got[k], v, rtol=rtol, atol=0, err_msg=k, strict=True)


def test_presets_both_models_unchanged(mk, reference):
    """paper-2.3, -4.1, -4.2 over 2 s, elastic and rigid: every saved output, bit for bit."""
    _compare(mk.trajectories(), reference, "paper-")


def test_scan_with_sensitivities_unchanged(mk, reference):
    """64-member friction scan of paper-4.2 with d_<observable>: values, sensitivities, status, steps."""
    _compare(mk.scan(), reference, "scan/")
