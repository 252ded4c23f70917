"""A second process that sends an emulated motor bursts of commands at random instants (seeded).

``python burst_client.py can GROUP SEED FRAMES`` sends FRAMES servo-mode CAN frames to driver 1 on the
udp_multicast group GROUP; ``python burst_client.py pty PATH SEED FRAMES`` writes FRAMES VESC frames to the pty
PATH. Bursts of 1..64 frames, back to back, separated by pauses of 0..10 ms, all drawn from ``random.Random(SEED)``.
The CAN mix is what real clients send (SET_CURRENT, SET_RPM, SET_POS, SET_POS_SPD, SET_DUTY, SET_ORIGIN_HERE, the
MIT-style power-on/off frames on extended IDs, an unknown packet 7) plus frames for another driver. The pty mix
is SET_CURRENT, SET_RPM, SET_POS, GET_VALUES, ALIVE. Then a marker command, and the client waits until the motor
reports it (:data:`MARKER_A`). Prints one JSON line: frames sent, marker frames, bursts, seconds to send and to
catch up.
"""

import json
import os
import random
import struct
import sys
import time


def can_frames(rng):
    """(arbitration_id, data) of one frame for driver 1 (or another driver), extended IDs."""
    kind = rng.randrange(10)
    if kind == 0:
        return (1 << 8) | 1, struct.pack(">i", rng.randint(-3000, 3000))  # SET_CURRENT mA
    if kind == 1:
        return (3 << 8) | 1, struct.pack(">i", rng.randint(-2000, 2000))  # SET_RPM
    if kind == 2:
        return (4 << 8) | 1, struct.pack(">i", rng.randint(-300_000, 300_000))  # SET_POS deg x 10000
    if kind == 3:
        return (6 << 8) | 1, struct.pack(">ihh", rng.randint(-300_000, 300_000), 500, 2000)  # SET_POS_SPD
    if kind == 4:
        return (0 << 8) | 1, struct.pack(">i", rng.randint(-5000, 5000))  # SET_DUTY
    if kind == 5:
        return (5 << 8) | 1, bytes([rng.randrange(3)])  # SET_ORIGIN_HERE
    if kind == 6:
        return 1, b"\xff" * 7 + bytes([rng.choice((0xFC, 0xFD))])  # power on / off (MIT-style, extended ID)
    if kind == 7:
        return (7 << 8) | 1, bytes([rng.choice((1, 3, 4, 7))])  # the SDK's mode switch: unknown packet 7
    if kind == 8:
        return (1 << 8) | 2, struct.pack(">i", 1000)  # another driver's command
    return (1 << 8) | 1, struct.pack(">i", 0)


def vesc_frame(rng):
    from protocol import vesc

    kind = rng.randrange(5)
    if kind == 0:
        msg = vesc.SetCurrent(rng.uniform(-3, 3))
    elif kind == 1:
        msg = vesc.SetRpm(rng.randint(-2000, 2000))
    elif kind == 2:
        msg = vesc.SetPos.from_degrees(rng.uniform(-30, 30))
    elif kind == 3:
        msg = vesc.GetValues()
    else:
        msg = vesc.Alive()
    return msg.encode()


MARKER_A = 4.47
"""The last commands: SET_CURRENT +4.47 A, then -4.47 A (outside the bursts' +-3 A). The client waits until the motor
reports each (held over several status frames), i.e. until the emulator has caught up with every frame before them,
so that its counts can be compared with what was sent. The marker is sent again while the client waits (every
:data:`MARKER_PERIOD_S` over CAN, with each GET_VALUES on the pty), as a control loop sends its command: a reversal
frees the rotor in
the gearbox's backlash, and the plant's model of it (hal/virtual/plant/gap.py) ends the crossing at the next
command."""
MARKER_PERIOD_S = 0.01


def wait_can(bus, deadline):
    import can

    sent = 0
    for sign in (1, -1):  # +4.47 A then -4.47 A, each held in 5 status frames in a row: no loop does that
        target = sign * MARKER_A
        marker = can.Message(arbitration_id=(1 << 8) | 1, data=struct.pack(">i", round(target * 1000)),
                             is_extended_id=True)
        held, next_send, seen = 0, 0.0, []
        while held < 5:
            now = time.monotonic()
            if now > deadline:
                raise SystemExit(f"the emulator did not catch up within the deadline: waiting for {target} A, "
                                 f"{len(seen)} status frames, the last currents {seen[-8:]}")
            if now >= next_send:
                bus.send(marker)
                sent += 1
                next_send = now + MARKER_PERIOD_S
            msg = bus.recv(MARKER_PERIOD_S)
            if msg is not None and msg.arbitration_id == (0x29 << 8) | 1 and len(msg.data) == 8:
                current = struct.unpack(">hhhbB", bytes(msg.data))[2] / 100
                held = held + 1 if abs(current - target) < 0.05 else 0
                seen.append(current)
    return sent


def wait_pty(fd, deadline):
    import termios

    from protocol import vesc

    termios.tcflush(fd, termios.TCIFLUSH)  # the replies to the bursts' GET_VALUES
    decoder, sent = vesc.Decoder("from-motor"), 0
    while time.monotonic() < deadline:
        os.write(fd, vesc.SetCurrent(MARKER_A).encode() + vesc.GetValues().encode())  # as a control loop: see MARKER_A
        sent += 2
        time.sleep(0.02)
        os.set_blocking(fd, False)
        try:
            data = os.read(fd, 65536)
        except BlockingIOError:
            data = b""
        os.set_blocking(fd, True)
        for msg in decoder.feed(data):
            if isinstance(msg, vesc.Values) and abs(msg.avg_iq_a - MARKER_A) < 0.05:
                return sent
    raise SystemExit("the emulator did not catch up within the deadline")


def main():
    kind, target, seed, total = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
    rng = random.Random(seed)
    sent = bursts = others = specials = unknown = 0
    t0 = time.monotonic()
    if kind == "can":
        import can

        from hal.pycan import own_group_only

        bus = can.Bus(interface="udp_multicast", channel=target)
        own_group_only(bus)  # not the frames of other tests' groups on this host

        def send():
            nonlocal others, specials, unknown
            arbitration_id, data = can_frames(rng)
            others += arbitration_id & 0xFF != 1
            specials += arbitration_id == 1 and data[:7] == b"\xff" * 7
            unknown += arbitration_id >> 8 == 7
            bus.send(can.Message(arbitration_id=arbitration_id, data=data, is_extended_id=True))
    else:
        fd = os.open(target, os.O_RDWR | os.O_NOCTTY)

        def send():
            frame = memoryview(vesc_frame(rng))
            while frame:
                frame = frame[os.write(fd, frame):]
    while sent < total:
        for _ in range(min(rng.randint(1, 64), total - sent)):
            send()
            sent += 1
        bursts += 1
        time.sleep(rng.uniform(0.0, 0.010))
    t_sent = time.monotonic()
    if kind == "can":
        markers = wait_can(bus, t_sent + 60)
        bus.shutdown()
    else:
        markers = wait_pty(fd, t_sent + 60)
    print(json.dumps({"frames": sent, "to_driver": sent - others, "specials": specials,
                      "unknown": unknown, "markers": markers, "bursts": bursts, "send_s": round(t_sent - t0, 3),
                      "catch_up_s": round(time.monotonic() - t_sent, 3)}), flush=True)


if __name__ == "__main__":
    main()
