"""The spec of a fault campaign (`pafp faults SPEC.toml`): faults x onsets x durations x scenarios x safe states x
controllers x motor links, checked whole before any run (docs/safety.md)::

    [campaign]
    profile = "../firmware.toml"     # firmware profile, relative to the spec (default profiles/firmware.toml)
    criteria = "criteria.toml"       # acceptance criteria, relative to the spec (default profiles/faults/criteria.toml)
    seed = 0                         # run seed (sensor noise, jitter) and injector seed: 0..2^32-1
    onsets = [0.0, 0.125, 0.25]      # gait phase of the onset in the first whole stride, 0 <= phase < 1
    durations_s = [0.05, 0.2]        # how long each fault acts, (0, 10] s
    controllers = ["cascade"]        # shipped controllers
    links = ["uart", "can-servo"]    # motor links (firmware/drivers/motor_links.py)
    safe_states = ["graded", "brake"] # [safety] safe_state values side by side (default: the profile's); the
                                      # verdict judges the profile's own, the others are compared
    settle_s = 0.3                   # simulated time kept after the fault's end, (0, 5] s
    timeout_s = 120                  # wall seconds per point

    [[scenario]]
    name = "suspended"               # the foot hangs free (as `pafp run`)
    [[scenario]]
    name = "walk"                    # the ground's moment in stance for a walker of body_mass_kg
    body_mass_kg = 20
    [[scenario]]
    name = "walk"
    body_mass_kg = 80
    profile = "../designs/adult_80kg.toml"  # this scenario's firmware profile (a design profile: its plant too)

    [[fault]]
    name = "task_overrun"            # a name of hal.virtual.faults.INJECTORS; its parameters beside it
    factor = 50

Points are the product fault (outermost) x scenario x safe state x controller x link x duration x onset
(innermost), numbered from 0; a fault that names its links (the CAN bus faults) is paired only with those links,
and a safe state only with the links that offer it (firmware/safe_state.py).
"""

from __future__ import annotations

import hashlib
import itertools
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from firmware.config import DEFAULT_PROFILE
from firmware.drivers.motor_links import MOTOR_LINKS
from firmware.safe_state import SAFE_STATES, check_offered
from hal.virtual.faults import INJECTORS, injector_class, make_injector
from host_tools.studies.spec_values import SpecValues
from host_tools.studies.sweep_spec import SpecError
from profiles import profile_path

__all__ = ["DEFAULT_CRITERIA", "FaultPoint", "FaultSpec", "load_fault_spec"]

DEFAULT_CRITERIA = profile_path("faults/criteria.toml")
CAMPAIGN_KEYS = ("profile", "criteria", "seed", "onsets", "durations_s", "controllers", "links", "safe_states",
                 "settle_s", "timeout_s")
SCENARIOS = {"suspended": ("profile",), "walk": ("body_mass_kg", "profile")}
MAX_POINTS = 100_000


@dataclass(frozen=True)
class FaultPoint:
    """One campaign point: everything a worker needs (picklable; the profile's text travels with it)."""

    index: int
    fault: str
    params: tuple[tuple[str, Any], ...]
    scenario: str
    body_mass_kg: float
    controller: str
    link: str
    onset_phase: float
    duration_s: float
    seed: int
    settle_s: float
    timeout_s: float
    profile_name: str
    profile_text: str
    safe_state: str = ""  # the [safety] safe_state this point runs with ("": the profile's own)

    def label(self) -> str:
        """A short description for tables."""
        where = self.scenario if self.scenario == "suspended" else f"walk {self.body_mass_kg:g} kg"
        safe = f", safe state {self.safe_state}" if self.safe_state else ""
        return (f"{self.fault} at phase {self.onset_phase:g} for {self.duration_s * 1e3:g} ms, {where}, "
                f"{self.controller}, {self.link}{safe}")


@dataclass(frozen=True)
class FaultSpec:
    """A checked campaign spec."""

    path: Path
    profile: Path
    profile_text: str
    criteria: Path
    seed: int
    onsets: tuple[float, ...]
    durations_s: tuple[float, ...]
    controllers: tuple[str, ...]
    links: tuple[str, ...]
    scenarios: tuple[tuple[str, float, str, str], ...]  # name, body mass, profile path, profile text
    faults: tuple[tuple[str, tuple[tuple[str, Any], ...]], ...]
    settle_s: float
    timeout_s: float
    digest: str
    safe_states: tuple[str, ...] = ("",)  # "": the profile's own
    def points(self) -> list[FaultPoint]:
        """Every point, in index order."""
        out: list[FaultPoint] = []
        offered = _offers(self.links)
        for (name, params), (scen, mass, prof, text), safe, ctrl, link, dur, onset in itertools.product(
                self.faults, self.scenarios, self.safe_states, self.controllers, self.links, self.durations_s,
                self.onsets):
            links = injector_class(name).LINKS
            if (links and link not in links) or (safe and safe not in offered[link]):
                continue
            out.append(FaultPoint(len(out), name, params, scen, mass, ctrl, link, onset, dur, self.seed,
                                  self.settle_s, self.timeout_s, prof, text, safe))
        return out

    @property
    def n_points(self) -> int:
        """How many points."""
        return len(self.points())


KIND = "fault spec"
_SPEC = SpecValues(KIND, "[campaign]")
_err, _number, _list = _SPEC.error, _SPEC.number, _SPEC.nonempty_list


def load_fault_spec(path: Path) -> FaultSpec:
    """Read and check a campaign spec; SpecError (one line naming the value, the key and the range) otherwise."""
    path = Path(path)
    text, doc = _SPEC.read(path, ("[campaign]", "[[scenario]]", "[[fault]]"))
    camp = doc.get("campaign", {})
    bad = sorted(set(camp) - set(CAMPAIGN_KEYS))
    if bad:
        raise SpecError(f"fault spec {path}: [campaign] key {bad[0]!r} unknown: one of {', '.join(CAMPAIGN_KEYS)}")
    profile = _SPEC.file(path, "[campaign] profile", camp["profile"]) if "profile" in camp else DEFAULT_PROFILE
    criteria = _SPEC.file(path, "[campaign] criteria", camp["criteria"]) if "criteria" in camp else DEFAULT_CRITERIA
    seed = camp.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**32:
        raise _err(path, "[campaign] seed", seed, f"an int in 0..{2**32 - 1}")
    onsets = tuple(_number(path, "[campaign] onsets", v, 0.0, 0.999999) for v in _list(path, camp, "onsets", [0.0]))
    durations = tuple(_number(path, "[campaign] durations_s", v, 0.0, 10.0, True)
                      for v in _list(path, camp, "durations_s", [0.1]))
    controllers = tuple(_list(path, camp, "controllers", ["cascade"]))
    from firmware.control.registry import CONTROLLERS

    for c in controllers:
        _SPEC.choice(path, "[campaign] controllers", c, CONTROLLERS)
    links = tuple(_list(path, camp, "links", ["uart"]))
    for link in links:
        _SPEC.choice(path, "[campaign] links", link, MOTOR_LINKS)
    settle = _number(path, "[campaign] settle_s", camp.get("settle_s", 0.3), 0.0, 5.0, True)
    timeout = _number(path, "[campaign] timeout_s", camp.get("timeout_s", 120.0), 0.0, 86_400.0, True)
    safe_states = tuple(_list(path, camp, "safe_states", [""]))
    for safe in safe_states:
        if safe != "" and safe not in SAFE_STATES:
            raise _err(path, "[campaign] safe_states", safe, f"one of {', '.join(SAFE_STATES)}")
    profile_text = Path(profile).read_text(encoding="utf-8")
    scenarios = []
    for k, s in enumerate(doc.get("scenario", [{"name": "suspended"}])):
        name = _SPEC.choice(path, f"[[scenario]] {k} name", s.get("name"), SCENARIOS)
        extra = sorted(set(s) - {"name", *SCENARIOS[name]})
        if extra:
            raise SpecError(f"fault spec {path}: [[scenario]] {k} ({name}) key {extra[0]!r} unknown")
        mass = _number(path, f"[[scenario]] {k} body_mass_kg", s.get("body_mass_kg", 80.0), 1.0, 300.0)
        prof, text = Path(profile), profile_text
        if "profile" in s:
            prof = _SPEC.file(path, f"[[scenario]] {k} profile", s["profile"])
            text = prof.read_text(encoding="utf-8")
        scenarios.append((name, mass, str(prof), text))
    faults = []
    for k, f in enumerate(doc.get("fault", [])):
        name = _SPEC.choice(path, f"[[fault]] {k} name", f.get("name"), INJECTORS)
        params = tuple(sorted((key, v) for key, v in f.items() if key != "name"))
        try:
            make_injector(name, 0.0, 1.0, seed, **dict(params))
        except ValueError as e:
            raise SpecError(f"fault spec {path}: [[fault]] {k}: {e}") from None
        faults.append((name, params))
    if not faults:
        raise SpecError(f"fault spec {path}: no [[fault]]: name at least one of {', '.join(INJECTORS)}")
    texts = [text, profile_text, Path(criteria).read_text(encoding="utf-8"), *(s[3] for s in scenarios)]
    digest = hashlib.sha256("\0".join(texts).encode()).hexdigest()
    spec = FaultSpec(path, Path(profile), profile_text, Path(criteria), seed, onsets, durations, controllers, links,
                     tuple(scenarios), tuple(faults), settle, timeout, digest, safe_states)
    n = spec.n_points
    if not 1 <= n <= MAX_POINTS:
        raise SpecError(f"fault spec {path}: {n} points out of range: 1..{MAX_POINTS} (no fault applies to the "
                        "links given?)" if n == 0 else f"fault spec {path}: {n} points out of range: 1..{MAX_POINTS}")
    return spec


def _offers(links: tuple[str, ...]) -> dict[str, tuple[str, ...]]:
    """The safe behaviours each link's driver offers (a safe state is paired only with the links offering it)."""
    out = {}
    for link in links:
        offered = MOTOR_LINKS.load(link, "links").SAFE_BEHAVIOURS
        out[link] = tuple(s for s in SAFE_STATES if _offered(s, offered, link))
    return out


def _offered(safe_state: str, offered: tuple[str, ...], link: str) -> bool:
    try:
        check_offered(safe_state, offered, link)
    except ValueError:
        return False
    return True
