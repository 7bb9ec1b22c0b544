"""What the command-line modules share: the program name, float64 set-up, the tolerance help texts and the
`--solver` choices."""

from __future__ import annotations

import diffrax

from ..._numerics.rosenbrock import RosenbrockW

PROG = "jaxhoist"

CLI_SOLVERS = {  # `--solver` name -> solver class (`jaxhoist scan`, `jaxhoist identify`)
    "rosenbrock-w": RosenbrockW,
    "tsit5": diffrax.Tsit5,
    "bosh3": diffrax.Bosh3,
    "dopri5": diffrax.Dopri5,
    "dopri8": diffrax.Dopri8,
    "heun": diffrax.Heun,
}


def enable_x64() -> None:
    import jax

    jax.config.update("jax_enable_x64", True)


RTOL_HELP = (
    "relative tolerance of the adaptive step-size control: each step's local error estimate must stay "
    "below atol + rtol |y| in every state component"
)
ATOL_HELP = (
    "absolute tolerance of the adaptive step-size control, in the state's SI units (m, m/s, rad, ...); "
    "it matters where a component is near zero"
)
