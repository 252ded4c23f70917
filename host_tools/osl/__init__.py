"""Clients of the Open Source Leg ecosystem on pafp's emulated bench.

* :mod:`host_tools.osl.can_bus`: run an SDK that hard-codes ``socketcan``/``can0`` (opensourceleg's
  ``TMotorServoActuator``, TMotorCANControl's managers) unchanged on any python-can bus, e.g. the
  ``udp_multicast`` one `pafp emulate motor --can` serves on.
* :mod:`host_tools.osl.virtual_leg`: a virtual Open Source Leg in process, opensourceleg's actuator, encoder, load
  cell and IMU interfaces on pafp's plant, drive and ground (docs/osl.md); :mod:`host_tools.osl.example_controller`,
  an ankle impedance state machine written against the OSL API only; :mod:`host_tools.osl.walk_osl` walks it.
"""
