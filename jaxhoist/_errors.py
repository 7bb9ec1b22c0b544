"""Errors and solver status codes shared by every layer."""

import enum


class ScenarioError(ValueError):
    """A scenario value or file is invalid. The message names the field, e.g. `rope.stiffness`."""


class Float64Error(RuntimeError):
    """jaxhoist needs 64-bit floats and they are not enabled."""


X64_HINT = (
    "jaxhoist needs float64 (stiff contact forces, tolerances near 1e-8). Enable it before "
    "creating any array: `jax.config.update('jax_enable_x64', True)` at the top of your script, "
    "or set the environment variable JAX_ENABLE_X64=1."
)


def require_x64() -> None:
    """Raise `Float64Error` unless `jax_enable_x64` is on."""
    import jax

    if not jax.config.read("jax_enable_x64"):
        raise Float64Error(X64_HINT)


class SolveStatus(enum.IntEnum):
    """Outcome of one solve, stored as an int in `Trajectory.status` (one per member in a scan)."""

    OK = 0
    MAX_STEPS = 1
    NONFINITE = 2
    SOLVER_FAILED = 3

    @property
    def message(self) -> str:
        return _MESSAGES[self]


_MESSAGES = {
    SolveStatus.OK: "ok",
    SolveStatus.MAX_STEPS: "the solver reached max_steps before t1 (raise max_steps, or loosen rtol/atol)",
    SolveStatus.NONFINITE: "the state became non-finite (NaN or inf): check the parameters and tolerances",
    SolveStatus.SOLVER_FAILED: "the solver failed (step size collapsed or an internal error)",
}
