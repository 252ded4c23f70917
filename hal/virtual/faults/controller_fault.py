"""What the controller faults share: a wrapper around the controller the firmware is given."""

from __future__ import annotations

from typing import Any

from hal.virtual.faults.base import FaultRig, Injector

__all__ = ["ControllerFault", "FaultyController"]


class FaultyController:
    """The controller, with ``update`` handed to the fault in its window (every other attribute passed through)."""

    def __init__(self, inner: Any, fault: ControllerFault) -> None:
        """Wrap inner."""
        self._inner, self._fault = inner, fault

    def update(self, obs: Any) -> object:
        """The inner controller's output, or the fault's in the window."""
        if self._fault.active(obs.t_s):
            return self._fault.misbehave(obs)
        return self._inner.update(obs)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._inner, name)


class ControllerFault(Injector):
    """A software fault of the controller (a stand-in for a defect in a plugged-in control law)."""

    WHERE = "controller (the control law the firmware calls)"

    def arm(self, rig: FaultRig) -> None:
        """Wrap the rig's controller (the runner has built the profile's when none was given)."""
        if rig.controller is None:
            raise ValueError(f"fault {self.NAME}: the rig has no controller to wrap")
        rig.controller = FaultyController(rig.controller, self)

    def misbehave(self, obs: Any) -> object:
        """What the faulty controller does in the window (subclasses; noted)."""
        raise NotImplementedError
