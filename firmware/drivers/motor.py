"""AK60-6 motor driver: commands and feedback through the VESC codec, with reply accounting.

Each control tick the motor task calls `poll` (decode what arrived), then `send` (one write with the
current or brake command followed by a feedback request). Feedback normally comes from
GET_VALUES_SELECTIVE with a small mask, so command + request + reply fit one period at 921600 baud;
every `full_every`-th request is a full GET_VALUES (temperatures, voltage); its 78-byte reply takes
most of a period at 921600 baud, so the next period sends its command without a request.

Receive timeout: the codec, like VESC's own decoder, waits for as many bytes as a frame header
announces, so a false header in line noise (``03 01 FF``: 511 bytes) would hold every good reply
behind it for many periods. A candidate frame still pending after the longest reply's wire time plus
one period (1.8 ms at 921600 baud) is given up (`Decoder.skip_pending`, counted in `rx_timeouts`).
"""

from __future__ import annotations

from typing import ClassVar, Final

from firmware.config import FirmwareConfig
from firmware.drivers.motor_link import MotorFeedback, MotorLink, MotorLinkStats, SafeStop, stop_command
from firmware.safe_state import SafeCommand
from hal.errors import HalError
from hal.interfaces import Board, Uart
from protocol.vesc import (
    Decoder,
    GetValues,
    GetValuesSelective,
    Message,
    SetCurrent,
    SetCurrentBrake,
    SetDuty,
    SetHandbrake,
    SetPos,
    Values,
    ValuesSelective,
)
from protocol.vesc_codec import MessageCodec
from protocol.vesc_values import selective_layout

__all__ = ["FEEDBACK_MASK", "MotorDriver", "MotorFeedback", "MotorLinkStats", "SafeStop", "safe_message",
           "selective_reply_bytes"]

# The longest reply the driver asks for: the 73-byte GET_VALUES payload, 78 bytes on the wire.
LONGEST_REPLY_BYTES: Final = len(Values().encode())
# avg_iq (bit 5), erpm (7), fault (15), pid_pos (16): 18-byte payload, 23 bytes on the wire.
FEEDBACK_MASK: Final = (1 << 5) | (1 << 7) | (1 << 15) | (1 << 16)


def selective_reply_bytes(mask: int, mask_echo: bool = True) -> int:
    """Bytes on the wire of a GET_VALUES_SELECTIVE reply for `mask` (frame overhead included)."""
    return 1 + (4 if mask_echo else 0) + selective_layout(mask & 0x3FFFFF)[0].size + 5


_COMMAND_BYTES: Final = len(SetCurrent(0.0).encode())  # SET_CURRENT and SET_CURRENT_BRAKE: 10 bytes


class MotorDriver(MotorLink):
    """Talks to the AK60-6 over `uart`; owns no timing: callers pass the time in seconds."""

    SAFE_BEHAVIOURS: ClassVar[tuple[str, ...]] = ("release", "brake", "short", "handbrake", "hold")

    def __init__(self, uart: Uart, *, full_every: int = 100, feedback_mask: int = FEEDBACK_MASK) -> None:
        """Prepare the codec and the constant request frames."""
        if full_every < 0:
            raise ValueError(f"full_every {full_every!r} out of range: >= 0 (0 = never)")
        self.uart = uart
        self.full_every = full_every
        self.decoder = Decoder("from-motor")
        self.feedback = MotorFeedback()
        self.stats = MotorLinkStats()
        self._current_codec: MessageCodec = SetCurrent.codec()  # frames straight from the float
        self._brake_codec: MessageCodec = SetCurrentBrake.codec()
        self._selective_request = GetValuesSelective(feedback_mask).encode()
        self._full_request = GetValues().encode()
        self._pending_since: float | None = None
        self._held_since: float | None = None
        # a candidate frame pending longer than the longest reply's wire time plus a period is line noise
        self.hold_timeout_s = LONGEST_REPLY_BYTES * 10 / uart.baud + 0.001
        self._count = 0
        self._skip_request = False
        # when the last command frame was accepted whole by the port (None: never): its age is how long
        # the motor has been applying an old command, which the supervisor bounds
        self.last_command_s: float | None = None

    @classmethod
    def from_board(cls, board: Board, config: FirmwareConfig) -> MotorDriver:
        """The driver on the board's motor UART, a full GET_VALUES at the profile's full_values_hz."""
        return cls(board.motor_uart, full_every=max(1, config.control_hz // config.full_values_hz))

    def relink(self, uart: Uart) -> None:
        """Continue on a reopened port (the supervisor's latched fault is not cleared)."""
        self.uart = uart
        self._relinked()
        self.decoder = Decoder("from-motor")
        self._pending_since, self._skip_request = None, False

    def poll(self, now_s: float) -> int:
        """Decode every byte that has arrived; return the number of feedback replies taken."""
        try:
            data = self.uart.read()
        except HalError as exc:
            self._lose(exc, now_s)
            return 0
        messages = self.decoder.feed(data) if data else []
        if messages or not self.decoder.buffered:
            self._held_since = None
        elif self._held_since is None:
            self._held_since = now_s
        elif now_s - self._held_since > self.hold_timeout_s:  # a false header holds the replies back
            self.stats.rx_timeouts += 1
            self._held_since = None
            messages = self.decoder.skip_pending()
        if not messages:
            return 0
        taken = 0
        fb = self.feedback
        for msg in messages:
            if isinstance(msg, ValuesSelective):
                v = msg.values
                fb.current_a = v.get("avg_iq_a", fb.current_a)
                fb.erpm = int(v.get("erpm", fb.erpm))  # int fields decode as int
                fb.position_rad = v.get("pid_pos_rad", fb.position_rad)
                fb.fault = int(v.get("fault", fb.fault))
            elif isinstance(msg, Values):
                fb.current_a, fb.erpm, fb.position_rad = msg.avg_iq_a, msg.erpm, msg.pid_pos_rad
                fb.fault, fb.temp_motor_c, fb.temp_fet_c = msg.fault, msg.temp_motor_c, msg.temp_fet_c
                fb.v_in_v = msg.v_in_v
                fb.temp_received_s = now_s
                self.stats.full_replies += 1
            else:
                continue
            taken += 1
            self._reply(now_s)
        return taken

    def _reply(self, now_s: float) -> None:
        """Book one reply: its age against the outstanding request, or stale if none was outstanding."""
        st = self.stats
        if self._pending_since is None:
            st.stale_replies += 1
            return
        st.replies += 1
        age = now_s - self._pending_since
        self.feedback.received_s = now_s
        if age > st.max_age_s:
            st.max_age_s = age
        self._pending_since = None

    def send(self, current_a: float, now_s: float, *, brake: bool = False, request: bool = True) -> int:
        """Write the current (or brake) command, then a feedback request; return bytes written."""
        return self._write((self._brake_codec if brake else self._current_codec).frame((current_a,)), now_s, request)

    def send_safe(self, command: SafeCommand, now_s: float, *, request: bool = True) -> int:
        """Write the safe state's command (SET_CURRENT 0, SET_CURRENT_BRAKE, SET_DUTY 0, SET_HANDBRAKE, SET_POS), then a
        feedback request (the policy reads the drive's fault and load in SAFE too); return bytes written."""
        return self._write(safe_message(command).encode(), now_s, request)

    def _write(self, frame: bytes, now_s: float, request: bool) -> int:
        """Write one command frame and, if asked, the feedback request after it; return bytes written."""
        if request and self._skip_request:  # a full reply is still on the wire: let it finish
            request, self._skip_request = False, False
        if request:
            if self._pending_since is not None:
                self.stats.missing_replies += 1
            full = self.full_every and self._count % self.full_every == 0
            frame += self._full_request if full else self._selective_request
            self._skip_request = bool(full)
            self._count += 1
            self.stats.requests += 1
            self._pending_since = now_s
        try:
            written = self.uart.write(frame)
        except HalError as exc:
            self._lose(exc, now_s)
            return 0
        if written < len(frame):
            self.stats.tx_refused += 1
        if written >= _COMMAND_BYTES:  # the command leads the frame: it went out whole
            self.last_command_s = now_s
        return written

    def send_stop(self, now_s: float, command: SafeCommand | float, timeout_s: float = 0.5) -> SafeStop:
        """The stop path: zero current, then the safe command (a number: the brake current), in one write; wait
        until both have left the UART.

        No feedback request follows: nothing will read a reply. A failing port is latched as lost.
        """
        cmd = stop_command(command)
        names = [repr(SetCurrent(0.0))]
        data = self._current_codec.frame((0.0,))
        if cmd.behaviour != "release":
            message = safe_message(cmd)
            data += message.encode()
            names.append(repr(message))
        stop = SafeStop(data, now_s, tuple(names))
        try:
            stop.written = self.uart.write(data)
            stop.drained = self.uart.flush(timeout_s)
        except HalError as exc:
            self._lose(exc, now_s)
            stop.error = str(exc)
        if stop.written < len(data):
            self.stats.tx_refused += 1
        elif stop.written:
            self.last_command_s = now_s
        return stop

    @property
    def crc_errors(self) -> int:
        """Frames the codec rejected for a bad CRC."""
        return self.decoder.stats.crc_errors


def safe_message(command: SafeCommand) -> Message:
    """The VESC command of a safe behaviour: SET_CURRENT_BRAKE, SET_DUTY 0, SET_HANDBRAKE, SET_POS (hold) or
    SET_CURRENT 0 (release)."""
    behaviour = command.behaviour
    if behaviour == "hold":
        return SetPos(command.position_rad)
    if behaviour == "brake":
        return SetCurrentBrake(command.current_a)
    if behaviour == "short":
        return SetDuty(0.0)
    if behaviour == "handbrake":
        return SetHandbrake(command.current_a)
    return SetCurrent(0.0)
