"""The rules every landmark catalog obeys, checked in one place.

Names are unique; the reference pair (L1, L2 of the landmark frame FL) is two different names of
the catalog. The session document, scenario files, the estimator and anything else that takes a
catalog ask :func:`catalog_problem` and raise their own error class with its answer.
"""

from __future__ import annotations

from collections.abc import Sequence


def catalog_problem(
    names: Sequence[str], reference: Sequence[str] | None = None
) -> tuple[str, str] | None:
    """What is wrong with a catalog and its reference pair, or None.

    Parameters
    ----------
    names : sequence of str
        Landmark names in catalog order.
    reference : (str, str), optional
        The reference pair, if there is one to check.

    Returns
    -------
    (field, problem) or None
        ``field`` is ``landmarks[i].name`` or ``reference``; ``problem`` a phrase for one line.
    """
    seen: set[str] = set()
    for i, name in enumerate(names):
        if name in seen:
            return f"landmarks[{i}].name", f"duplicate landmark name {name!r} (names are unique)"
        seen.add(name)
    if reference is None:
        return None
    if len(reference) != 2:
        return "reference", f"expected two landmark names, got {list(reference)}"
    for r in reference:
        if r not in seen:
            return "reference", f"{r!r} is not a landmark of the catalog (have {list(names)})"
    if reference[0] == reference[1]:
        return "reference", f"the two reference landmarks must differ, got {list(reference)}"
    return None
