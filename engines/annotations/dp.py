"""Dynamic programming over time slots (Arikan, Forsyth & O'Brien 2003, Eqs. 3-4).

Each time slot ``k`` has an active set of ``M`` candidate blocks; ``unary[k, i]`` is the cost of
playing candidate ``i`` in slot ``k`` (``alpha * sum D`` over its frames) and ``pair(k)[a, b]`` the
cost of following candidate ``a`` of slot ``k - 1`` by candidate ``b`` of slot ``k``
(``(1 - alpha) * C``). The cost-to-go ``J(k, b) = unary[k, b] + min_a (J(k - 1, a) + pair(k)[a, b])``
is computed one slot at a time as a minimum over an ``(M, M)`` matrix (vectorized over candidates),
and the optimum is read back along the stored argmins. Exact for the given active sets.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]


def solve_chain(unary: FloatArray, pair: Callable[[int], FloatArray]) -> tuple[IntArray, float]:
    """The cheapest choice of one candidate per slot.

    Parameters
    ----------
    unary: ``(K, M)`` cost of each candidate of each slot.
    pair: ``pair(k)`` for ``k >= 1`` is the ``(M, M)`` cost of candidate ``a`` in slot ``k - 1``
        followed by candidate ``b`` in slot ``k``.

    Returns
    -------
    choice: ``(K,)`` the chosen candidate per slot.
    cost: its total cost.
    """
    k_slots, m = unary.shape
    back = np.zeros((k_slots, m), dtype=np.intp)
    j = unary[0].astype(np.float64, copy=True)
    for k in range(1, k_slots):
        total = j[:, None] + pair(k)
        arg = np.argmin(total, axis=0)
        back[k] = arg
        j = total[arg, np.arange(m)] + unary[k]
    choice = np.zeros(k_slots, dtype=np.intp)
    choice[-1] = int(np.argmin(j))
    cost = float(j[choice[-1]])
    for k in range(k_slots - 1, 0, -1):
        choice[k - 1] = back[k, choice[k]]
    return choice, cost
