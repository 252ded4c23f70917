"""The kernel: clocks, cooperative fixed-priority scheduler, trace, statistics, analysis.

Times are integer CPU cycles everywhere; a smaller priority number means a higher priority.
"""

from rtos.clock import Clock, VirtualClock, WallClock
from rtos.interrupts import InterruptSource, PeriodicInterrupt, TimestampedInterrupt, solve_finish
from rtos.scheduler import Scheduler
from rtos.stats import Blocker, InterruptStats, TaskStats, Utilisation
from rtos.task import Fault, Job, OverrunError, OverrunPolicy, Task
from rtos.trace import JobRecord, Trace, TraceEvent
from rtos.watchdog import Watchdog

__all__ = [
    "Blocker", "Clock", "Fault", "InterruptSource", "InterruptStats", "Job", "JobRecord", "OverrunError",
    "OverrunPolicy", "PeriodicInterrupt", "Scheduler", "Task", "TaskStats", "TimestampedInterrupt", "Trace",
    "TraceEvent", "Utilisation", "VirtualClock", "WallClock", "Watchdog", "solve_finish",
]
