"""The application that would be flashed: the task table and the events from outside it.

Tasks (smaller priority number = higher priority), all released together each control period so
that, cooperatively, one period runs: encoder -> supervisor -> control -> motor; the IMU, logger and
watchdog tasks run at lower rates. Costs are cycle estimates from the firmware profile (to calibrate
with DWT->CYCCNT on a real board). The task bodies are in :mod:`firmware.tasks`. The firmware is handed
a `Board`; it never imports a backend.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

from firmware.config import CostModel, FirmwareConfig
from firmware.control.interface import check_controller
from firmware.control.reference import GaitReference
from firmware.drivers.motor_link import SafeStop
from firmware.safety import FaultReason
from firmware.tasks import ControlOutput, FirmwareTasks, KernelHealth
from hal.interfaces import Board
from rtos import Job, OverrunPolicy, Task

log = logging.getLogger(__name__)

__all__ = ["ControlOutput", "Firmware", "KernelHealth"]


def _plus(cost: int | Callable[[object], int], extra: int) -> int | Callable[[object], int]:
    """A cost (cycles, a CostModel or any cost callable) priced extra cycles more."""
    if isinstance(cost, int):
        return cost + extra
    if isinstance(cost, CostModel):
        return CostModel(cost.base + extra, cost.per_byte)
    model = cost
    return lambda handled: model(handled) + extra


class Firmware(FirmwareTasks):
    """The prosthesis firmware bound to `board`: build it, then hand `tasks` to the RTOS."""

    def __init__(self, board: Board, config: FirmwareConfig, reference: GaitReference | None = None,
                 controller: object = None) -> None:
        """Bind drivers to the board's peripherals, take the controller (default: the profile's), build the table."""
        super().__init__(board, config, reference, controller)
        self.tasks = self._task_table()

    # The task table ---------------------------------------------------------------------------
    def _task_table(self) -> list[Task]:
        c, f = self.config, self.f_cpu_hz

        def task(name: str, prio: int, hz: int, body: Callable[[Job], object]) -> Task:
            cost: int | Callable[[object], int] = c.cost(name)
            own = getattr(self.controller, "cost_cycles", None) if name == "control" else None
            if isinstance(own, int):
                check_controller(self.controller, f // hz)
                cost = own
            if name == "control" and self.ground_events is not None:  # the ground sensors read in the control task
                cost = _plus(cost, c.ground_sensors.cost_cycles)
            if isinstance(cost, CostModel) and not cost.per_byte:
                cost = cost.base  # a fixed cost: the kernel need not call the model for every job
            return Task(name, prio, period=f // hz, cost=cost, body=body, overrun=OverrunPolicy.SKIP)

        return [
            task("encoder", 1, c.control_hz, self.encoder_task),
            task("supervisor", 2, c.control_hz, self.supervisor_task),
            task("control", 3, c.control_hz, self.control_task),
            task("motor", 4, c.control_hz, self.motor_task),
            task("imu", 5, c.imu_poll_hz, self.imu_task),
            task("logger", 6, c.logger_hz, self.logger_task),
            task("watchdog", 7, c.watchdog_kick_hz, self.watchdog_task),
        ]

    # Events from outside the task table ----------------------------------------------------------
    def stop(self, now_s: float, timeout_s: float = 0.5) -> SafeStop:
        """The stop path (power-down, end of run): zero current then the safe state's command, on the wire before
        returning."""
        return self.motor.send_stop(now_s, self.supervisor.policy.stop_command(), timeout_s)

    def on_watchdog_reset(self, t_cycles: int) -> None:
        """The IWDG fired: count it and latch the safe state (a real MCU would reboot into INIT)."""
        self.watchdog_resets += 1
        self.supervisor.trip(FaultReason.WATCHDOG, self.seconds(t_cycles))

    def on_task_fault(self, task_name: str, t_cycles: int) -> None:
        """A task overran its budget under the FAULT policy: latch the safe state."""
        self.supervisor.trip(FaultReason.TASK_OVERRUN, self.seconds(t_cycles))
