"""Clients of the Open Source Leg ecosystem on pafp's emulated bench.

* :mod:`host_tools.osl.can_bus`: run an SDK that hard-codes ``socketcan``/``can0`` (opensourceleg's
  ``TMotorServoActuator``, TMotorCANControl's managers) unchanged on any python-can bus, e.g. the
  ``udp_multicast`` one `pafp emulate motor --can` serves on.
"""
