"""jaxtyping aliases used across jaxhoist (shapes only; dtypes are float64 by policy)."""

from jaxtyping import Array, Float

Scalar = Float[Array, ""]
Vec3 = Float[Array, "3"]
Quat = Float[Array, "4"]
Rot33 = Float[Array, "3 3"]
PerCorner = Float[Array, "4"]
CornerVecs = Float[Array, "4 3"]
CornerVecs2 = Float[Array, "4 2"]
