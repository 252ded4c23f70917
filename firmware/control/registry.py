"""Controllers by name: the shipped ones in one registry, and a user's class from ``FILE.py:CLASS``.

A new shipped controller is a new module plus one entry in :data:`CONTROLLERS`: a function of the
firmware configuration and the profile's ``[controller]`` parameters that returns the controller. A
separate package adds one through the entry-point group ``pafp.controllers``; its entry may also name a
controller class, built as a ``FILE.py:CLASS`` one is (docs/control.md).
"""

from __future__ import annotations

import importlib.util
import inspect
import sys
from pathlib import Path
from typing import Any

from firmware.config import FirmwareConfig
from firmware.control.interface import check_controller
from hal.registry import Registry

__all__ = ["CONTROLLERS", "build_cascade", "build_controller", "load_class"]


def build_cascade(config: FirmwareConfig, params: dict[str, Any]) -> object:
    """The cascaded position PID -> velocity PI controller of the profile's gains (it takes no parameters)."""
    from firmware.control.cascade import Cascade
    from firmware.control.pid import Feedforward

    if params:
        raise ValueError(f"controller cascade takes no [controller] parameters (got {sorted(params)}): its gains "
                         "are [control.position] and [control.velocity]")
    c = config
    return Cascade(c.position_gains, c.velocity_gains, 1.0 / c.control_hz, c.current_limit_a, c.velocity_limit_rad_s,
                   Feedforward(c.feedforward_params) if c.feedforward else None, c.com_angle_rad)


CONTROLLERS = Registry("controller", {
    "cascade": "firmware.control.registry:build_cascade",
    "impedance": "firmware.control.impedance:impedance_from_config",
    "sysid": "firmware.control.sysid:sysid_from_config",
}, group="pafp.controllers")
"""Shipped controllers: name -> factory(config, params), or a controller class (built as FILE.py:CLASS)."""


def load_class(spec: str) -> type:
    """The class CLASS of ``FILE.py:CLASS``; ValueError naming the file, the class and what is wrong."""
    file, sep, name = spec.rpartition(":")
    if not sep or not file.endswith(".py") or not name.isidentifier():
        raise ValueError(f"controller {spec!r} is neither one of {CONTROLLERS.names()} nor FILE.py:CLASS")
    path = Path(file)
    if not path.is_file():
        raise ValueError(f"controller file {file!r} not found")
    module_name = f"pafp_user_controller_{abs(hash(str(path.resolve())))}"
    mod_spec = importlib.util.spec_from_file_location(module_name, path)
    if mod_spec is None or mod_spec.loader is None:
        raise ValueError(f"controller file {file!r} cannot be loaded as a Python module")
    module = importlib.util.module_from_spec(mod_spec)
    sys.modules[module_name] = module  # dataclasses and pickling look the module up by name
    try:
        mod_spec.loader.exec_module(module)
    except Exception as e:  # the user's file: any error is reported as one line
        del sys.modules[module_name]
        raise ValueError(f"controller file {file!r} failed to load: {type(e).__name__}: {e}") from None
    cls = getattr(module, name, None)
    if not isinstance(cls, type):
        classes = sorted(k for k, v in vars(module).items() if isinstance(v, type) and v.__module__ == module_name)
        raise ValueError(f"controller file {file!r} has no class {name!r}: it defines {classes}")
    return cls


def _construct(cls: type, params: dict[str, Any], spec: str) -> object:
    """cls(params) when the constructor takes one argument, cls() when it takes none (then no params)."""
    try:
        sig = inspect.signature(cls)
    except (TypeError, ValueError):
        sig = None
    takes = 0 if sig is None else sum(
        p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD) for p in sig.parameters.values())
    try:
        if takes == 0:
            if params:
                raise ValueError(f"controller {spec}: its constructor takes no argument, so the [controller] "
                                 f"parameters {sorted(params)} cannot be passed")
            return cls()
        return cls(dict(params))
    except ValueError:
        raise
    except Exception as e:
        raise ValueError(f"controller {spec}: constructor raised {type(e).__name__}: {e}") from None


def build_controller(spec: str, config: FirmwareConfig, params: dict[str, Any] | None = None) -> object:
    """The controller named spec (a shipped name or FILE.py:CLASS), built with params, checked."""
    params = dict(params or {})
    if not isinstance(spec, str):
        raise ValueError(f"controller {spec!r} is not a name: one of {CONTROLLERS.names()} or FILE.py:CLASS")
    if spec in CONTROLLERS:
        made = CONTROLLERS.load(spec)
        controller = _construct(made, params, spec) if isinstance(made, type) else made(config, params)
    else:
        controller = _construct(load_class(spec), params, spec)
    check_controller(controller)
    return controller
