"""`pafp fit`'s memo of simulations: within one fit (`one_fit`), a simulation already run with the same base
profile, parameter values and recording is taken from the memo, not run again.

A fit asks for the same simulation again where its steps meet: the solver's Jacobian at the point it stopped and the
intervals' Jacobian there, the cost of that point in the next step (the noise scales, a profile's centre, the
adequacy check, the fit percentages). The memo holds the last MEMO_SIZE simulations, keyed by the objects' identity
(held by the memo, so not reused while it holds them) and the values' bits: a simulation from it is the very one.
Outside `one_fit` nothing is remembered.
"""

from __future__ import annotations

import functools
from collections import OrderedDict
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np

__all__ = ["MEMO_SIZE", "one_fit", "remembered"]

MEMO_SIZE = 64  # simulations held (a recording of 30 s: about 0.3 MB each)
_memo: OrderedDict | None = None  # key -> (base, recording, outputs, heard): the fit's under way; None outside one


@contextmanager
def one_fit() -> Iterator[None]:
    """Within: `remembered` simulations are taken from the memo of this fit (one memo for nested calls)."""
    global _memo
    outer = _memo
    _memo = OrderedDict() if outer is None else outer
    try:
        yield
    finally:
        _memo = outer


def remembered(simulate: Callable[..., tuple[np.ndarray, ...]]) -> Callable[..., tuple[np.ndarray, ...]]:
    """`simulate(base, v, exp, *args, heard_out=None, **kwargs)` taken from the memo within `one_fit`; each call gets
    its own copies of the arrays."""

    @functools.wraps(simulate)
    def wrapper(base: Any, v: dict[str, float], exp: Any, *args: Any, heard_out: np.ndarray | None = None,
                **kwargs: Any) -> tuple[np.ndarray, ...]:
        if _memo is None:
            return simulate(base, v, exp, *args, heard_out=heard_out, **kwargs)
        key = (id(base), id(exp), args, tuple(sorted(kwargs.items())),
               tuple((name, float(x).hex()) for name, x in sorted(v.items())))
        hit = _memo.get(key)
        if hit is None:
            heard = np.zeros(len(exp.t), dtype=bool)
            hit = (base, exp, simulate(base, v, exp, *args, heard_out=heard, **kwargs), heard)
            _memo[key] = hit
            if len(_memo) > MEMO_SIZE:
                _memo.popitem(last=False)
        else:
            _memo.move_to_end(key)
        if heard_out is not None:
            heard_out[:] = hit[3]
        return tuple(a.copy() for a in hit[2])

    return wrapper
