"""Board binding: which backend serves each peripheral, chosen by a URL-like string per role.

In the manner of pyserial URLs and python-can interface names: one registry table maps a scheme
to a backend factory. Built in:

* ``sim://[model]``  the in-process virtual backend; the optional ``context`` (the virtual bench
  the integrator wires) builds the peripheral: ``context.virtual_uart(role, model, baud)``,
  ``virtual_encoder(role, model)``, ``virtual_digital_in(role, model)``, ``virtual_digital_out(role, model)``;
* ``null://``        a harmless stand-in (UART to nowhere, still encoder, pin tied low);
* anything pyserial opens, UART roles only: a device path (``/dev/ttyUSB0``, ``COM3``) or a
  pyserial URL (``loop://``, ``socket://host:port``, ``rfc2217://host:port``, ``spy:///dev/ttyUSB0``,
  ``hwgrep://...``, or a scheme of a package added to ``serial.protocol_handler_packages``).

>>> parse_spec("motor", "sim://ak60-6")
PeripheralSpec(role='motor', kind='uart', url='sim://ak60-6', scheme='sim', target='ak60-6')
>>> parse_spec("imu", "/dev/ttyUSB1").scheme
'pyserial'
"""

from __future__ import annotations

import importlib.util
import logging
import re
from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass
from typing import Any, Protocol

from hal.interfaces import Board, DigitalIn, DigitalOut, EncoderTimer, Uart, Watchdog

__all__ = [
    "ALLOWED_FORMS",
    "BackendFactory",
    "PYSERIAL",
    "PeripheralSpec",
    "ROLE_KINDS",
    "SimContext",
    "VIRTUAL_BENCH",
    "backends",
    "bind_board",
    "open_peripheral",
    "open_uart",
    "parse_spec",
    "register_backend",
    "unregister_backend",
]

log = logging.getLogger(__name__)

ROLE_KINDS: Mapping[str, str] = {
    "motor": "uart",
    "imu": "uart",
    "telemetry": "uart",
    "encoder": "encoder",
    "estop": "digital_in",
    "led": "digital_out",
}
_KIND_TYPES: Mapping[str, type] = {
    "uart": Uart,
    "encoder": EncoderTimer,
    "digital_in": DigitalIn,
    "digital_out": DigitalOut,
}
PYSERIAL = "pyserial"  # the registry key serving device paths and pyserial URLs
VIRTUAL_BENCH: Mapping[str, str] = {
    "motor": "sim://ak60-6",
    "imu": "sim://bno08x",
    "telemetry": "sim://",
    "encoder": "sim://",
    "estop": "sim://",
    "led": "sim://",
}
ALLOWED_FORMS = (
    "sim://[model], null://, a device path (/dev/ttyUSB0, COM3) or a pyserial URL "
    "(loop://, socket://host:port, rfc2217://host:port, spy:///dev/ttyUSB0, ...)"
)
_URL = re.compile(r"([A-Za-z][A-Za-z0-9+.-]*)://(.*)", re.DOTALL)
_DEVICE_PATH = re.compile(r"/[^\s]+|COM[0-9]+|\\\\\.\\COM[0-9]+")


@dataclass(frozen=True)
class PeripheralSpec:
    """One parsed binding: the role, its peripheral kind, the string, the backend and its target."""

    role: str
    kind: str
    url: str
    scheme: str
    target: str


BackendFactory = Callable[[PeripheralSpec, "int | None", Any], object]


class SimContext(Protocol):
    """What the sim:// backend asks of the virtual bench (only the methods for the kinds bound)."""

    def virtual_uart(self, role: str, model: str, baud: int) -> Uart:
        """The MCU-side UART for role, wired to the device model named model ('' = none)."""
        ...

    def virtual_encoder(self, role: str, model: str) -> EncoderTimer:
        """The encoder timer reading the plant."""
        ...

    def virtual_digital_in(self, role: str, model: str) -> DigitalIn:
        """An input pin of the bench (e.g. the e-stop)."""
        ...

    def virtual_digital_out(self, role: str, model: str) -> DigitalOut:
        """An output pin of the bench (e.g. the LED)."""
        ...


_SIM_METHODS = {
    "uart": "virtual_uart",
    "encoder": "virtual_encoder",
    "digital_in": "virtual_digital_in",
    "digital_out": "virtual_digital_out",
}


def _open_sim(spec: PeripheralSpec, baud: int | None, context: Any) -> object:
    method = _SIM_METHODS[spec.kind]
    build = getattr(context, method, None)
    if build is None:
        raise ValueError(
            f"{spec.role} = {spec.url!r}: sim:// needs a context (the virtual bench) with {method}(); "
            f"got {type(context).__name__}"
        )
    if spec.kind == "uart":
        return build(spec.role, spec.target, baud)
    return build(spec.role, spec.target)


def _open_null(spec: PeripheralSpec, baud: int | None, context: Any) -> object:
    from hal.virtual.null import NullDigitalIn, NullDigitalOut, NullEncoderTimer, NullUart

    if spec.target:
        raise ValueError(f"{spec.role} = {spec.url!r}: null:// takes no target; write 'null://'")
    if spec.kind == "uart":
        assert baud is not None
        return NullUart(baud, name=f"null:{spec.role}")
    if spec.kind == "encoder":
        return NullEncoderTimer()
    return NullDigitalIn(False) if spec.kind == "digital_in" else NullDigitalOut()


def _open_pyserial(spec: PeripheralSpec, baud: int | None, context: Any) -> object:
    from hal.serial.backend import SerialUart

    assert baud is not None
    return SerialUart(spec.url, baud)


_BACKENDS: dict[str, tuple[BackendFactory, frozenset[str]]] = {
    "sim": (_open_sim, frozenset(ROLE_KINDS.values())),
    "null": (_open_null, frozenset(ROLE_KINDS.values())),
    PYSERIAL: (_open_pyserial, frozenset({"uart"})),
}


def register_backend(
    scheme: str, factory: BackendFactory, *, kinds: Collection[str] | None = None, replace: bool = False
) -> None:
    """Serve scheme:// bindings with factory(spec, baud, context) for the given kinds (default: all)."""
    if not isinstance(scheme, str) or not _URL.fullmatch(f"{scheme}://") or scheme != scheme.lower():
        raise ValueError(f"scheme {scheme!r} invalid: lower-case letters, digits, '+', '-', '.'")
    if scheme in _BACKENDS and not replace:
        raise ValueError(f"scheme {scheme!r} already registered; pass replace=True to override")
    chosen = frozenset(ROLE_KINDS.values()) if kinds is None else frozenset(kinds)
    unknown = chosen - set(_KIND_TYPES)
    if unknown:
        raise ValueError(f"kinds {sorted(unknown)} unknown; allowed: {sorted(_KIND_TYPES)}")
    _BACKENDS[scheme] = (factory, chosen)


def unregister_backend(scheme: str) -> None:
    """Remove a registered scheme (the built-in ones included)."""
    if _BACKENDS.pop(scheme, None) is None:
        raise ValueError(f"scheme {scheme!r} not registered; registered: {backends()}")


def backends() -> tuple[str, ...]:
    """The registered schemes, sorted."""
    return tuple(sorted(_BACKENDS))


def _pyserial_knows(scheme: str) -> bool:
    import serial

    if scheme == "fault":  # our fault-injecting wrapper: its package is listed when first asked for
        from hal.serial.protocol_fault import register_fault_handler

        register_fault_handler()

    for package in serial.protocol_handler_packages:
        try:
            if importlib.util.find_spec(f"{package}.protocol_{scheme}") is not None:
                return True
        except (ImportError, ValueError):
            continue
    return False


def parse_spec(role: str, url: str) -> PeripheralSpec:
    """Parse the binding string url for role; ValueError naming it and the allowed forms if invalid."""
    if role not in ROLE_KINDS:
        raise ValueError(f"role {role!r} unknown; allowed: {', '.join(ROLE_KINDS)}")
    kind = ROLE_KINDS[role]
    if not isinstance(url, str) or not url or url != url.strip() or any(c in url for c in "\r\n\t\0"):
        raise ValueError(f"{role} = {url!r} invalid; allowed: {ALLOWED_FORMS}")
    match = _URL.fullmatch(url)
    if match is not None:
        scheme, target = match.group(1).lower(), match.group(2)
        if scheme in _BACKENDS and scheme != PYSERIAL:
            pass
        elif _pyserial_knows(scheme):
            scheme, target = PYSERIAL, url
        else:
            raise ValueError(
                f"{role} = {url!r}: scheme {scheme!r} unknown (registered: {', '.join(backends())}; "
                f"nor a pyserial handler); allowed: {ALLOWED_FORMS}"
            )
    elif _DEVICE_PATH.fullmatch(url):
        scheme, target = PYSERIAL, url
    else:
        raise ValueError(f"{role} = {url!r} is neither a URL nor a device path; allowed: {ALLOWED_FORMS}")
    if kind not in _BACKENDS[scheme][1]:
        served = "a serial port" if scheme == PYSERIAL else f"{scheme}://"
        raise ValueError(
            f"{role} = {url!r}: {served} cannot serve peripheral kind {kind!r}; use sim:// or null://"
        )
    return PeripheralSpec(role, kind, url, scheme, target)


def open_peripheral(role: str, url: str, *, baud: int | None = None, context: Any = None) -> object:
    """Open the peripheral for role from its binding string (baud is required for UART roles)."""
    spec = parse_spec(role, url)
    if spec.kind == "uart" and baud is None:
        raise ValueError(f"{role} = {url!r}: a UART needs a baud rate")
    factory = _BACKENDS[spec.scheme][0]
    peripheral = factory(spec, baud, context)
    expected = _KIND_TYPES[spec.kind]
    if not isinstance(peripheral, expected):
        raise TypeError(
            f"{role} = {url!r}: backend {spec.scheme!r} returned {type(peripheral).__name__}, "
            f"not a {expected.__name__}"
        )
    log.debug("bound %s to %s (%s)", role, url, type(peripheral).__name__)
    return peripheral


def open_uart(url: str, baud: int, *, role: str = "motor", context: Any = None) -> Uart:
    """Open one UART from its binding string (the role picks the sim:// device)."""
    if ROLE_KINDS.get(role) != "uart":
        raise ValueError(f"role {role!r} is not a UART role; UART roles: motor, imu, telemetry")
    uart = open_peripheral(role, url, baud=baud, context=context)
    assert isinstance(uart, Uart)
    return uart


def bind_board(
    binding: Mapping[str, str],
    *,
    bauds: Mapping[str, int],
    watchdog: Watchdog,
    now_cycles: Callable[[], int],
    f_cpu_hz: int,
    context: Any = None,
) -> Board:
    """Open every role of binding (all six roles required) and bundle them into a Board."""
    missing = [r for r in ROLE_KINDS if r not in binding]
    unknown = [r for r in binding if r not in ROLE_KINDS]
    if missing or unknown:
        raise ValueError(
            f"binding roles wrong (missing {missing}, unknown {unknown}); required: {', '.join(ROLE_KINDS)}"
        )
    no_baud = [r for r, k in ROLE_KINDS.items() if k == "uart" and r not in bauds]
    if no_baud:
        raise ValueError(f"bauds lacks {no_baud}; every UART role needs a baud rate")
    opened: dict[str, object] = {}
    try:
        for role, kind in ROLE_KINDS.items():
            baud = bauds[role] if kind == "uart" else None
            opened[role] = open_peripheral(role, binding[role], baud=baud, context=context)
    except BaseException:
        for peripheral in opened.values():
            if isinstance(peripheral, Uart):
                peripheral.close()
        raise
    return Board(
        motor_uart=opened["motor"],  # type: ignore[arg-type]
        imu_uart=opened["imu"],  # type: ignore[arg-type]
        telemetry_uart=opened["telemetry"],  # type: ignore[arg-type]
        encoder=opened["encoder"],  # type: ignore[arg-type]
        estop=opened["estop"],  # type: ignore[arg-type]
        led=opened["led"],  # type: ignore[arg-type]
        watchdog=watchdog,
        now_cycles=now_cycles,
        f_cpu_hz=f_cpu_hz,
    )
