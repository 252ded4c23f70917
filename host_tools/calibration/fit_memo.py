"""`pafp fit`'s memo of simulations: within one fit (`one_fit`), a simulation already run with the same base
profile, parameter values and recording is taken from the memo, not run again (`remembered`); so is a window's run of
the plant (`recall`, keyed by what it depends on: `fit_window.window_key`).

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
from contextvars import ContextVar
from typing import Any

import numpy as np

__all__ = ["MEMO_SIZE", "WINDOW_MEMO_SIZE", "one_fit", "recall", "remembered"]

MEMO_SIZE = 64  # simulations held (a recording of 30 s: about 0.3 MB each)
WINDOW_MEMO_SIZE = 4096  # windows' runs held (about 3 kB each)
# the fit's under way (None outside one; a thread's own): simulations, key -> (base, recording, outputs, heard), and
# windows' runs, key -> (what the key names by identity, the run)
_memos: ContextVar[tuple[OrderedDict, OrderedDict] | None] = ContextVar("fit_memos", default=None)


@contextmanager
def one_fit() -> Iterator[None]:
    """Within: `remembered` simulations are taken from the memo of this fit (one memo for nested calls)."""
    if _memos.get() is not None:
        yield
        return
    token = _memos.set((OrderedDict(), OrderedDict()))
    try:
        yield
    finally:
        _memos.reset(token)


def _held(memo: OrderedDict, key: tuple, make: Callable[[], Any], size: int) -> Any:
    """memo[key], made by `make` when it is not there; the least recently used dropped beyond `size`."""
    hit = memo.get(key)
    if hit is None:
        hit = memo[key] = make()
        if len(memo) > size:
            memo.popitem(last=False)
    else:
        memo.move_to_end(key)
    return hit


def recall(key: tuple, keep: tuple, run: Callable[[], Any]) -> Any:
    """run() or, within `one_fit`, what it returned for the same key (`keep`: the objects the key names by identity,
    held with it). The caller must not change what it returns."""
    memos = _memos.get()
    if memos is None:
        return run()
    return _held(memos[1], key, lambda: (keep, run()), WINDOW_MEMO_SIZE)[1]


def remembered(simulate: Callable[..., tuple[np.ndarray, ...]]) -> Callable[..., tuple[np.ndarray, ...]]:
    """`simulate(base, v, exp, *args, heard_out=None, **kwargs)` taken from the memo within `one_fit`; each call gets
    its own copies of the arrays."""

    @functools.wraps(simulate)
    def wrapper(base: Any, v: dict[str, float], exp: Any, *args: Any, heard_out: np.ndarray | None = None,
                **kwargs: Any) -> tuple[np.ndarray, ...]:
        memos = _memos.get()
        if memos is None:
            return simulate(base, v, exp, *args, heard_out=heard_out, **kwargs)
        key = (id(base), id(exp), args, tuple(sorted(kwargs.items())),
               tuple((name, float(x).hex()) for name, x in sorted(v.items())))

        def run() -> tuple:
            heard = np.zeros(len(exp.t), dtype=bool)
            return base, exp, simulate(base, v, exp, *args, heard_out=heard, **kwargs), heard

        hit = _held(memos[0], key, run, MEMO_SIZE)
        if heard_out is not None:
            heard_out[:] = hit[3]
        return tuple(a.copy() for a in hit[2])

    return wrapper
