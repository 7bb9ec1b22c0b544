"""Errors and solver status codes shared by every layer."""

import contextlib
import enum

MAX_MESSAGE_CHARS = 600
"""The longest error line a `ScenarioError` carries [characters]; longer messages lose their middle."""


def one_line(msg: str, limit: int = MAX_MESSAGE_CHARS) -> str:
    """`msg` on one line (line breaks become spaces), at most `limit` characters.

    A longer message keeps its start (which names the field) and its end (which names the file and table)
    and says how many characters were left out in between.

    **Arguments**
    - `msg`: the message.
    - `limit`: the longest result [characters], at least 100.

    **Returns** the shortened one-line message.
    """
    msg = " ".join(str(msg).splitlines())
    if len(msg) <= limit:
        return msg
    tail = limit // 4
    width = len(f" ... [{len(msg)} characters omitted] ... ")  # the marker's longest possible length
    head = limit - tail - width
    marker = f" ... [{len(msg) - head - tail} characters omitted] ... "
    return msg[:head] + marker + msg[len(msg) - tail :]


class ScenarioError(ValueError):
    """A scenario value or file is invalid. The message names the field, e.g. `rope.stiffness`.

    The message is kept to one line of at most `MAX_MESSAGE_CHARS` characters (see `one_line`), however
    large the offending value.
    """

    def __init__(self, *args):
        if len(args) == 1 and isinstance(args[0], str):
            args = (one_line(args[0]),)
        super().__init__(*args)


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
    """Outcome of one solve, stored as an int in `Trajectory.status` (one per member in a scan).

    - `OK`: the solve reached t1 with a finite state and passed the a-posteriori checks.
    - `MAX_STEPS`, `NONFINITE`, `SOLVER_FAILED`: the solver failed (diffrax's result, a non-finite state).
    - `ENERGY_BALANCE`: the solver reported success, but the energy balance
      E(t) - E(0) = W_hoist - D_damping - W_friction does not close: its residual relative to the energy
      that flowed exceeds `jaxhoist._physics.energy.BALANCE_BOUND` (the solution is wrong, e.g. a rope so
      stiff that the solver stepped over its force entirely).
    """

    OK = 0
    MAX_STEPS = 1
    NONFINITE = 2
    SOLVER_FAILED = 3
    ENERGY_BALANCE = 4

    @property
    def message(self) -> str:
        return _MESSAGES[self]


_MESSAGES = {
    SolveStatus.OK: "ok",
    SolveStatus.MAX_STEPS: "the solver reached max_steps before t1 (raise max_steps, or loosen rtol/atol)",
    SolveStatus.NONFINITE: "the state became non-finite (NaN or inf): check the parameters and tolerances",
    SolveStatus.SOLVER_FAILED: "the solver failed (step size collapsed or an internal error)",
    SolveStatus.ENERGY_BALANCE: (
        "the solver reported success but the energy balance does not close (residual above 5 % of the "
        "energy that flowed): the result is wrong; check implausible parameters, or tighten rtol/atol"
    ),
}


FORWARD_MODE_HINT = (
    "forward-mode differentiation (jax.jacfwd, jax.jvp) cannot pass through the default reverse-mode "
    "adjoint of the solve: call simulate(..., options=SolverOptions(adjoint=diffrax.ForwardMode())) for "
    "jacfwd/jvp; keep the default for jax.grad"
)


def is_forward_through_custom_vjp(error: BaseException) -> bool:
    """True if `error` is JAX's refusal to apply forward-mode autodiff to a `custom_vjp` function (what
    `jax.jacfwd` through diffrax's `RecursiveCheckpointAdjoint` raises).

    **Arguments**
    - `error`: any exception.

    **Returns** whether it is that `TypeError`.
    """
    text = str(error)
    return isinstance(error, TypeError) and "forward-mode autodiff" in text and "custom_vjp" in text


@contextlib.contextmanager
def forward_mode_hint():
    """Re-raise JAX's "can't apply forward-mode autodiff (jvp) to a custom_vjp function" as a `TypeError`
    that says to pass `adjoint=diffrax.ForwardMode()`; every other exception passes through unchanged.

    Wrap the call of the solve core with it (`with forward_mode_hint(): traj = _solve_jit(...)`).

    **Raises** `TypeError` with `FORWARD_MODE_HINT` (the original error chained as its cause).
    """
    try:
        yield
    except TypeError as e:
        if is_forward_through_custom_vjp(e):
            raise TypeError(FORWARD_MODE_HINT) from e
        raise
