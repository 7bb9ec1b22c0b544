"""What the command-line modules share: the program name, float64 set-up and the tolerance help texts."""

from __future__ import annotations

PROG = "jaxhoist"


def _enable_x64() -> None:
    import jax

    jax.config.update("jax_enable_x64", True)


_RTOL_HELP = (
    "relative tolerance of the adaptive step-size control: each step's local error estimate must stay "
    "below atol + rtol |y| in every state component"
)
_ATOL_HELP = (
    "absolute tolerance of the adaptive step-size control, in the state's SI units (m, m/s, rad, ...); "
    "it matters where a component is near zero"
)
