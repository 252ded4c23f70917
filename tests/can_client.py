"""A plain python-can program (no pafp import): drives an AK-series motor in MIT or servo mode on a bus.

``python can_client.py INTERFACE CHANNEL mit|servo [ID]`` prints one JSON line: what it saw. MIT mode:
enter motor mode, 0.4 s of a constant torque command, exit motor mode; reports the first and last
position in the replies. Servo mode: 0.3 s of SET_CURRENT 2 A every 2 ms; reports the last current in
the status frames. Layouts: CubeMars AK-series manual, CAN chapter (as in TMotorCANControl).
"""

import json
import struct
import sys
import time

import can


def f2u(x, lo, hi, bits):
    x = min(max(x, lo), hi)
    return int((x - lo) * ((1 << bits) - 1) / (hi - lo))


def u2f(u, lo, hi, bits):
    return u * (hi - lo) / ((1 << bits) - 1) + lo


def mit_command(p, v, kp, kd, t):
    p, v = f2u(p, -12.5, 12.5, 16), f2u(v, -50, 50, 12)
    kp, kd, t = f2u(kp, 0, 500, 12), f2u(kd, 0, 5, 12), f2u(t, -15, 15, 12)
    return bytes([p >> 8, p & 0xFF, v >> 4, ((v & 0xF) << 4) | (kp >> 8), kp & 0xFF, kd >> 4,
                  ((kd & 0xF) << 4) | (t >> 8), t & 0xFF])


def mit(bus, ident):
    positions = []
    bus.send(can.Message(arbitration_id=ident, data=b"\xff" * 7 + b"\xfc", is_extended_id=False))
    end = time.monotonic() + 0.4
    while time.monotonic() < end:
        bus.send(can.Message(arbitration_id=ident, data=mit_command(0, 0, 0, 0, 2.0), is_extended_id=False))
        deadline = time.monotonic() + 0.002
        while (msg := bus.recv(max(0.0, deadline - time.monotonic()))) is not None:
            d = msg.data
            if not msg.is_extended_id and len(d) >= 6 and d[0] == ident:
                positions.append(u2f((d[1] << 8) | d[2], -12.5, 12.5, 16))
    bus.send(can.Message(arbitration_id=ident, data=mit_command(0, 0, 0, 0, 0), is_extended_id=False))
    bus.send(can.Message(arbitration_id=ident, data=b"\xff" * 7 + b"\xfd", is_extended_id=False))
    return {"replies": len(positions), "first_p": positions[0] if positions else None,
            "last_p": positions[-1] if positions else None}


def servo(bus, ident):
    currents = []
    end = time.monotonic() + 0.3
    while time.monotonic() < end:
        bus.send(can.Message(arbitration_id=(1 << 8) | ident, data=struct.pack(">i", 2000), is_extended_id=True))
        deadline = time.monotonic() + 0.002
        while (msg := bus.recv(max(0.0, deadline - time.monotonic()))) is not None:
            if msg.is_extended_id and msg.arbitration_id == (0x29 << 8) | ident and len(msg.data) == 8:
                currents.append(struct.unpack(">hhhbB", bytes(msg.data))[2] / 100)
    bus.send(can.Message(arbitration_id=(1 << 8) | ident, data=struct.pack(">i", 0), is_extended_id=True))
    return {"status_frames": len(currents), "last_current_a": currents[-1] if currents else None}


def main():
    interface, channel, mode = sys.argv[1:4]
    ident = int(sys.argv[4]) if len(sys.argv) > 4 else 1
    with can.Bus(interface=interface, channel=channel) as bus:
        out = mit(bus, ident) if mode == "mit" else servo(bus, ident)
    print(json.dumps(out), flush=True)


if __name__ == "__main__":
    main()
