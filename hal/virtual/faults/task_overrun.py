"""Task overrun: a firmware task takes ``factor`` times its cycle cost (CPU overload, a slow flash wait, a bug)."""

from __future__ import annotations

from hal.virtual.faults.base import FaultRig, Injector

__all__ = ["TASKS", "TaskOverrun"]

TASKS = ("encoder", "supervisor", "control", "motor", "imu", "logger", "watchdog")


class TaskOverrun(Injector):
    """Every job of ``task`` started in the window costs ``factor`` times its modelled cycles."""

    NAME = "task_overrun"
    HAZARD = "late control periods: stale commands, missed deadlines, a starved watchdog"
    WHERE = "CPU (the task's cost model)"
    PARAMS = {"factor": (50.0, 1.0, 1000.0), "task": ("control", TASKS)}

    def arm(self, rig: FaultRig) -> None:
        """Scale the task's cost in the window."""
        f, factor = rig.f_cpu_hz, self.params["factor"]

        def scale(t_cycles: int) -> float:
            t_s = t_cycles / f
            if not self.active(t_s):
                return 1.0
            self.note(t_s, f"task {self.params['task']} cost x {factor:g}")
            return factor
        rig.cost_scales.setdefault(self.params["task"], []).append(scale)
