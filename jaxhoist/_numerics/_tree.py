"""Linear combinations of pytrees with static coefficients, for the Runge-Kutta and Rosenbrock stages."""

import jax


def lin_comb(terms, base=None, like=None):
    """base + Σ a_j x_j over pytrees (`terms`: list of (a_j, x_j) with Python-float a_j), skipping zero
    coefficients and written as one expression per leaf (so XLA fuses it). With no non-zero term: `base`,
    or zeros like `like` when `base` is None."""
    terms = [(float(a), x) for a, x in terms if a != 0.0]
    if not terms:
        return base if base is not None else jax.tree_util.tree_map(lambda x: 0.0 * x, like)

    def comb(*leaves):
        xs = leaves if base is None else leaves[1:]
        acc = terms[0][0] * xs[0]
        for (a, _), x in zip(terms[1:], xs[1:], strict=True):
            acc = acc + a * x
        return acc if base is None else leaves[0] + acc

    trees = [x for _, x in terms] if base is None else [base, *[x for _, x in terms]]
    return jax.tree_util.tree_map(comb, *trees)
