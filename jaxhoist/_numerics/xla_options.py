"""The XLA compiler options of the programs jaxhoist compiles itself: `compiler_options(platform)`.

On CPU, jaxhoist compiles its programs without XLA's fusion emitters (`xla_cpu_use_fusion_emitters=False`):
XLA then emits its fused loops the older way, which compiles the solve programs in 0.6-0.7x the time. The
programs run about as fast on the Intel machine of our measurements; on the AMD EPYC with AVX-512 a lock-step
scan group runs about 1.2x as long (docs/performance-design.md, "XLA's CPU fusion emitters are off", has the
measurements). The options apply where jaxhoist compiles a program at the top level: `simulate`'s solve core
and its forward-mode derivative, a scan's group programs, the bifurcation locator's solves, `identify`'s fit
pieces and the rigid model's pieces (`compile_cache`, `stored_programs`, the scan's `batch`), whether the
persistent compilation cache is on or off. A caller's own `jax.jit`, `jax.grad` or `jax.vmap` around
`simulate` compiles the caller's program with the caller's options (JAX takes compiler options on the
outermost `jit` only); `jax.jit(f, compiler_options={"xla_cpu_use_fusion_emitters": False})` gives it the
same.

The option changes the rounding of some fused operations, and an adaptive solver's steps follow the bits, so
a solve compiled with and without it differs by the local error (both are the same solution to the solver's
tolerance). Where a jaxlib does not know the option (XLA is retiring the older emitters), jaxhoist compiles
with XLA's defaults.
"""

from __future__ import annotations

import functools

import jax

#: The options jaxhoist compiles its CPU programs with (see the module docstring).
CPU_OPTIONS: dict[str, str | bool] = {"xla_cpu_use_fusion_emitters": False}


@functools.cache
def _supported() -> bool:
    """Whether this jaxlib's CPU compiler takes `CPU_OPTIONS`: a tiny program compiled with them once per
    process (a few milliseconds)."""
    try:
        with jax.default_device(jax.devices("cpu")[0]):
            jax.jit(lambda x: x + 1, compiler_options=CPU_OPTIONS).lower(0.0).compile()
    except Exception:  # noqa: BLE001  (an unknown option, or no CPU backend: XLA's defaults)
        return False
    return True


def compiler_options(platform: str | None = None) -> dict[str, str | bool]:
    """The XLA options for a program jaxhoist compiles at the top level for `platform` ("cpu", "gpu", ...;
    default: JAX's default backend): `CPU_OPTIONS` on CPU where this jaxlib takes them, else none (XLA's
    defaults). A new dict each call."""
    if (platform or jax.default_backend()) != "cpu" or not _supported():
        return {}
    return dict(CPU_OPTIONS)


def describe(options: dict[str, str | bool] | None = None) -> str:
    """`options` (default: those of `compiler_options()`) as one line of text, for the key of a stored
    program and the stamp of a reference recording; `describe({})` stands for XLA's defaults."""
    return f"compiler options {sorted((compiler_options() if options is None else options).items())}"
