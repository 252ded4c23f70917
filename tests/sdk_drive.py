"""Drive `pafp emulate motor --can` with a third-party SDK's own actuator class, unchanged (issue 37).

``python sdk_drive.py osl|tmcc GROUP SECONDS MOTOR_TYPE`` (run in a scratch directory: opensourceleg writes its
log file into the working directory). ``osl``: opensourceleg's ``TMotorServoActuator`` (servo mode); ``tmcc``:
TMotorCANControl's ``TMotorManager_mit_can`` (MIT mode). Both hard-code ``socketcan``/``can0``: the bus is swapped
for the udp_multicast group GROUP from outside (host_tools.osl.can_bus.redirected_can, what a vcan named can0
does). SECONDS are split in three phases: current steps (+-1 A every 0.5 s), velocity steps, position steps.
Prints one JSON object: per phase the commands and the readings (time, position, velocity, current, temperature,
error) the SDK reported after each update().
"""

import json
import math
import os
import sys
import time


def osl(seconds, motor_type, log):
    from opensourceleg.actuators.base import CONTROL_MODES
    from opensourceleg.actuators.tmotor import TMotorServoActuator

    motor = TMotorServoActuator(motor_type=motor_type, motor_id=1)
    phase_s = seconds / 3
    with motor:
        for mode, command in ((CONTROL_MODES.CURRENT, lambda k: motor.set_motor_current(1.0 if k % 2 else -1.0)),
                              (CONTROL_MODES.VELOCITY, lambda k: motor.set_motor_velocity(20.0 if k % 2 else -20.0)),
                              (CONTROL_MODES.POSITION, lambda k: motor.set_motor_position(math.radians(
                                  20_000.0 if k % 2 else -20_000.0)))):
            motor.set_control_mode(mode)
            rows = log.setdefault(mode.name.lower(), [])
            t0 = time.monotonic()
            while (t := time.monotonic() - t0) < phase_s:
                k = int(t / 0.5) + 1
                command(k)
                motor.update()
                rows.append([round(t, 4), k, motor.motor_position, motor.motor_velocity, motor.motor_current,
                             motor.case_temperature, motor._motor_state.error])
                time.sleep(0.005)
        motor.set_control_mode(CONTROL_MODES.CURRENT)
        motor.set_motor_current(0.0)


def tmcc(seconds, motor_type, log):
    os.system = lambda command: 0  # the manager runs `sudo ip link set can0 ...`: not here
    from TMotorCANControl.mit_can import TMotorManager_mit_can

    phase_s = seconds / 3
    with TMotorManager_mit_can(motor_type=motor_type, motor_ID=1) as dev:
        dev.set_zero_position()
        time.sleep(0.2)
        for name, setup, command in (
                ("current", lambda: dev.set_current_gains(), lambda k: dev.set_motor_current_qaxis_amps(
                    1.0 if k % 2 else -1.0)),
                ("velocity", lambda: dev.set_speed_gains(kd=2.0), lambda k: dev.set_output_velocity_radians_per_second(
                    2.0 if k % 2 else -2.0)),
                ("position", lambda: dev.set_impedance_gains_real_unit(K=10.0, B=0.5),
                 lambda k: dev.set_output_angle_radians(0.3 if k % 2 else -0.3))):
            setup()
            rows = log.setdefault(name, [])
            t0 = time.monotonic()
            while (t := time.monotonic() - t0) < phase_s:
                k = int(t / 0.5) + 1
                command(k)
                dev.update()
                rows.append([round(t, 4), k, dev.get_output_angle_radians(),
                             dev.get_output_velocity_radians_per_second(), dev.get_current_qaxis_amps(),
                             dev.get_temperature_celsius(), dev.get_motor_error_code()])
                time.sleep(0.005)
        dev.set_current_gains()
        dev.set_motor_current_qaxis_amps(0.0)
        dev.update()


def main():
    sdk, group, seconds, motor_type = sys.argv[1], sys.argv[2], float(sys.argv[3]), sys.argv[4]
    from host_tools.osl.can_bus import redirected_can

    log = {}
    with redirected_can(f"can://udp_multicast/{group}") as buses:
        (osl if sdk == "osl" else tmcc)(seconds, motor_type, log)
        echoes = sum(getattr(b, "echoes", 0) for b in buses)
    print(json.dumps({"sdk": sdk, "motor_type": motor_type, "echoes_dropped": echoes, "phases": log}), flush=True)
    os._exit(0)  # the SDKs' singletons keep notifier threads and buses open: leave without waiting on them


if __name__ == "__main__":
    main()
