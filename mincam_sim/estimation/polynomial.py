"""Polynomial features of a decoder: every monomial of a few variables up to a total degree (pure arithmetic).

Written with ``*`` and ``+`` only, so one implementation serves NumPy arrays (the decoders, their fits) and
Dr.Jit arrays (the mask optimiser's loss, traced for automatic differentiation): the same variables give the
same terms in the same order in both.
"""

from __future__ import annotations

from itertools import combinations_with_replacement


def poly_terms(*variables, degree: int = 3) -> list:
    """All monomials of ``variables`` of total degree <= ``degree``, the constant first.

    Order: by degree, then as :func:`itertools.combinations_with_replacement` of the variables' indices (two
    variables, degree 2: ``1, x, y, x^2, x y, y^2``); a monomial is the product of its factors from the left.

    Parameters
    ----------
    variables : arrays of one shape (NumPy or Dr.Jit) or floats
        The decoder's inputs (dimensionless features).
    degree : int
        Highest total degree (>= 0).

    Returns
    -------
    list
        The terms, each of the variables' shape; the constant is ``variables[0] * 0 + 1``: NaN where the first
        variable is not finite (for ``degree >= 1`` that variable's own term is not finite there either).
    """
    if not variables:
        raise ValueError("poly_terms needs at least one variable")
    if isinstance(degree, bool) or int(degree) != degree or degree < 0:
        raise ValueError(f"degree must be an integer >= 0, got {degree!r}")
    terms = [variables[0] * 0 + 1.0]
    for d in range(1, int(degree) + 1):
        for combo in combinations_with_replacement(range(len(variables)), d):
            t = variables[combo[0]]
            for i in combo[1:]:
                t = t * variables[i]
            terms.append(t)
    return terms


__all__ = ["poly_terms"]
