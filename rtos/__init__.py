"""The kernel: clocks, cooperative fixed-priority scheduler, trace, statistics, analysis."""
