"""The controller interface: what the control task calls, and how a failure of a controller is described.

A controller is any object with ``update(self, obs)`` that returns the motor current command in
amperes (a float; a positive current drives the angle positive) or a
:class:`~firmware.control.observation.MotorCommand`. Optional: ``reset(self)`` (called when the
supervisor enters RUN and when it enters SAFE), ``cost_cycles`` (an int: the control task's cost in CPU
cycles for the RTOS and the response-time analysis; default: the profile's ``[task_cycles] control``),
and ``published`` (a dict of name -> number: its keys as they are after construction become columns of
telemetry.csv, its values are logged with every telemetry record). ``obs`` is an
:class:`~firmware.control.observation.Observation`. docs/controllers.md has a complete example.
"""

from __future__ import annotations

import inspect
import math
import traceback
from typing import Any, Protocol

from firmware.control.observation import MotorCommand, Observation

__all__ = ["MAX_PUBLISHED", "Controller", "check_controller", "describe_failure", "published_names"]

MAX_PUBLISHED = 16
"""At most this many published values travel in each telemetry record (4 bytes each)."""


class Controller(Protocol):
    """What the control task needs of a controller."""

    def update(self, obs: Observation) -> float | MotorCommand:
        """The motor current command in A (or a MotorCommand) for this period."""


def controller_name(controller: object) -> str:
    """The controller's class name and where it is defined (``Class (file.py:line)``)."""
    cls = type(controller)
    try:
        where = f"{inspect.getsourcefile(cls)}:{inspect.getsourcelines(cls)[1]}"
    except (TypeError, OSError):
        where = cls.__module__
    return f"{cls.__qualname__} ({where})"


def check_controller(controller: object, control_period_cycles: int | None = None) -> None:
    """ValueError naming the controller unless it has update(), and a cost_cycles / published it may have
    are usable."""
    name = controller_name(controller)
    if not callable(getattr(controller, "update", None)):
        raise ValueError(f"controller {name} has no update(self, obs) method")
    reset = getattr(controller, "reset", None)
    if reset is not None and not callable(reset):
        raise ValueError(f"controller {name}: reset = {reset!r} is not a method")
    cost = getattr(controller, "cost_cycles", None)
    top = control_period_cycles or 10**9
    if cost is not None and (isinstance(cost, bool) or not isinstance(cost, int) or not 1 <= cost <= top):
        raise ValueError(f"controller {name}: cost_cycles = {cost!r} out of range: an int in 1..{top}"
                         + (" (the control period in CPU cycles)" if control_period_cycles else ""))
    published = getattr(controller, "published", None)
    if published is not None:
        if not isinstance(published, dict) or not all(isinstance(k, str) and k.isidentifier() for k in published):
            raise ValueError(f"controller {name}: published must be a dict whose keys are identifiers, "
                             f"not {published!r}")
        if len(published) > MAX_PUBLISHED:
            raise ValueError(f"controller {name}: {len(published)} published values, at most {MAX_PUBLISHED}")


def published_names(controller: object) -> tuple[str, ...]:
    """The names of the values the controller publishes (its ``published`` keys now), or ()."""
    published = getattr(controller, "published", None)
    return tuple(published) if isinstance(published, dict) else ()


def as_number(value: Any) -> float:
    """A published value as a float; NaN for anything that is not a real number."""
    try:
        return float(value) if not isinstance(value, (str, bytes)) else math.nan
    except (TypeError, ValueError, OverflowError):
        return math.nan


def describe_failure(controller: object, error: BaseException | None, returned: object = None) -> str:
    """One line: which controller failed, where (file:line) and how (an exception, or a bad return value)."""
    name = type(controller).__qualname__
    if error is not None:
        frames = traceback.extract_tb(error.__traceback__)
        try:
            own = inspect.getsourcefile(type(controller))
        except (TypeError, OSError):
            own = None
        mine = [f for f in frames if own is not None and f.filename == own]
        frame = mine[-1] if mine else frames[-1] if frames else None
        where = f"{frame.filename}:{frame.lineno}" if frame else "(no traceback)"
        return f"controller {name} raised {type(error).__name__}: {error} at {where}"
    update = getattr(type(controller), "update", None)
    code = getattr(update, "__code__", None)
    where = f"{code.co_filename}:{code.co_firstlineno}" if code is not None else controller_name(controller)
    return (f"controller {name}.update returned {returned!r} ({type(returned).__name__}) at {where}: "
            "need a finite float (amperes) or a MotorCommand")
