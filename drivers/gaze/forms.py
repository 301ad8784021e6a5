"""Polynomial forms for interpolation gaze mapping, as data (Blignaut 2014 and its sources).

A form is a tuple of monomial exponents (i, j), each meaning the term x^i y^j with its own
coefficient, where (x, y) is the normalised pupil-glint vector (dimensionless, see `blignaut`).
A screen coordinate is sum_k a_k x^i_k y^j_k. The catalogue below transcribes the table of
reference/gaze-algorithms.md section 2 (the terms as given by later open implementations citing
these papers; the 2014 paper's own table was not available):

    X1 / Y1  1, x / 1, y                          linear (Hoormann 2008)
    X2 = Y2  1, x, y, xy                          Hennessey 2008
    X3 = Y3  1, x, y, xy, x^2, y^2                second order (Cerrolaza 2008)
    X4 = Y4  1, x, y, xy, x^2, y^2, x^2y^2        second order + x^2y^2
    Y5       1, x, y, y^2                         Zhu & Ji 2005 (with X2)
    X5 / Y6  1, x, y, x^2 / 1, y, x^2, xy, x^2y   Cerrolaza & Villanueva 2008
    X6 / Y7  1, x, x^3, y^2, xy / 1, x, x^2, y, y^2, xy, x^2y   Blignaut & Wium 2013
    X7       1, x, x^2, x^3, y, xy, x^2y, x^3y    Blignaut 2013 (with Y7)

MODELS k = 1..8 are the rows of the published error table as (X form, Y form). Rows 9-12 use forms
(X9, Y8, Y9) derived in the 2014 paper whose terms are not available here. To add a form, build a
new mapping, e.g. `{**FORMS, "Y8": ((0, 0), (0, 1), ...)}`, or pass a tuple of exponents directly.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

import numpy as np

Form = tuple[tuple[int, int], ...]

_LINEAR_X: Form = ((0, 0), (1, 0))
_LINEAR_Y: Form = ((0, 0), (0, 1))
_BILINEAR: Form = ((0, 0), (1, 0), (0, 1), (1, 1))
_SECOND: Form = (*_BILINEAR, (2, 0), (0, 2))

#: The catalogue of forms (name -> monomial exponents (i, j) of x^i y^j).
FORMS: Mapping[str, Form] = MappingProxyType(
    {
        "X1": _LINEAR_X,
        "Y1": _LINEAR_Y,
        "X2": _BILINEAR,
        "Y2": _BILINEAR,
        "X3": _SECOND,
        "Y3": _SECOND,
        "X4": (*_SECOND, (2, 2)),
        "Y4": (*_SECOND, (2, 2)),
        "Y5": ((0, 0), (1, 0), (0, 1), (0, 2)),
        "X5": ((0, 0), (1, 0), (0, 1), (2, 0)),
        "Y6": ((0, 0), (0, 1), (2, 0), (1, 1), (2, 1)),
        "X6": ((0, 0), (1, 0), (3, 0), (0, 2), (1, 1)),
        "Y7": ((0, 0), (1, 0), (2, 0), (0, 1), (0, 2), (1, 1), (2, 1)),
        "X7": ((0, 0), (1, 0), (2, 0), (3, 0), (0, 1), (1, 1), (2, 1), (3, 1)),
    }
)

#: Published models (row k of Blignaut 2014's error table, as tabulated by Fischer et al. 2023).
MODELS: Mapping[int, tuple[str, str]] = MappingProxyType(
    {
        1: ("X1", "Y1"),
        2: ("X2", "Y2"),
        3: ("X3", "Y3"),
        4: ("X4", "Y4"),
        5: ("X2", "Y5"),
        6: ("X5", "Y6"),
        7: ("X6", "Y7"),
        8: ("X7", "Y7"),
    }
)


def check_form(form: object) -> Form:
    """`form` as a Form: a non-empty tuple of distinct (i, j) pairs of non-negative ints; else ValueError."""
    try:
        terms = tuple((int(i), int(j)) for i, j in form)  # type: ignore[union-attr]
    except (TypeError, ValueError) as exc:
        raise ValueError(f"a form is a sequence of (i, j) exponent pairs, got {form!r}") from exc
    if not terms or len(set(terms)) != len(terms) or min(min(t) for t in terms) < 0:
        raise ValueError(f"a form needs distinct non-negative exponent pairs, got {form!r}")
    return terms


def resolve_form(form: str | Form, forms: Mapping[str, Form] = FORMS) -> Form:
    """The exponents of a form given by name (looked up in `forms`) or directly."""
    if isinstance(form, str):
        if form not in forms:
            raise ValueError(f"unknown form {form!r}; known: {', '.join(forms)}")
        return check_form(forms[form])
    return check_form(form)


def describe(form: Form) -> str:
    """A readable sum of the form's terms, e.g. '1 + x + y + xy'."""
    def term(i: int, j: int) -> str:
        parts = [v if p == 1 else f"{v}^{p}" for v, p in (("x", i), ("y", j)) if p]
        return "".join(parts) or "1"

    return " + ".join(term(i, j) for i, j in form)


def design_matrix(form: Form, xy: np.ndarray) -> np.ndarray:
    """Term values (..., n_terms) of `form` at features xy (..., 2): column k = x^i_k y^j_k."""
    xy = np.asarray(xy, float)
    x, y = xy[..., 0], xy[..., 1]
    top = max(max(i, j) for i, j in form)
    xp, yp = [np.ones_like(x)], [np.ones_like(y)]
    for _ in range(top):  # integer powers by repeated products (exact, and no float pow)
        xp.append(xp[-1] * x)
        yp.append(yp[-1] * y)
    return np.stack([xp[i] * yp[j] for i, j in form], axis=-1)
