"""The controller interface: a user's class from a file, published values in telemetry.csv, and a failing
controller latching the safe state with an error that names it (runs of one stride)."""

from __future__ import annotations

import csv
import json
import math
import textwrap
from pathlib import Path

import pytest

from firmware.config import load_firmware_config
from firmware.control.cascade import Cascade
from firmware.control.observation import MotorCommand, Observation
from firmware.control.pid import CascadeController, Feedforward
from firmware.control.registry import build_controller
from firmware.safety import FaultReason, SupervisorState
from host_tools.cli import main
from host_tools.runner import RunConfig, run_virtual

USER = textwrap.dedent('''
    import math

    class PdGravity:
        cost_cycles = 2500

        def __init__(self, params):
            self.k = params.get("k_nm_per_rad", 60.0)
            self.b = params.get("b_nm_s_per_rad", 1.5)
            self.nm_per_a = 0.078 * 28.0 * 0.855
            self.published = {"torque_nm": 0.0, "error_deg": 0.0}
            self.resets = 0

        def reset(self):
            self.resets += 1

        def update(self, obs):
            error = obs.reference_rad - obs.angle_rad
            torque = (self.k * error + self.b * (obs.reference_velocity_rad_s - obs.velocity_rad_s)
                      + 1.176 * 9.8 * 0.150 * math.cos(obs.reference_rad))
            self.published["torque_nm"] = torque
            self.published["error_deg"] = math.degrees(error)
            return torque / self.nm_per_a

    class Raises:
        def update(self, obs):
            if obs.t_s > 1.0:
                return {}["missing"]
            return 0.0

    class ReturnsNan:
        def update(self, obs):
            return math.nan if obs.t_s > 1.0 else 0.0

    class ReturnsText:
        def update(self, obs):
            return "1 A"

    class Brakes:
        def update(self, obs):
            return __import__("firmware.control.observation").control.observation.MotorCommand(1.0, brake=True)
''')


@pytest.fixture(scope="module")
def user_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("ctl") / "user_ctl.py"
    path.write_text(USER, encoding="utf-8")
    return path


def _run(spec: str, strides: int = 1, params: dict | None = None):
    fw_cfg = load_firmware_config()
    ctl = build_controller(spec, fw_cfg, params)
    return run_virtual(RunConfig(strides=strides, firmware=fw_cfg, controller=ctl, trace_capacity=0))


def test_cascade_behind_the_interface_gives_the_loops_own_commands():
    cfg = load_firmware_config()
    ff = Feedforward(cfg.feedforward_params)
    wrapped = Cascade(cfg.position_gains, cfg.velocity_gains, 1e-3, 12.0, 8.0, ff, cfg.com_angle_rad)
    bare = CascadeController(cfg.position_gains, cfg.velocity_gains, 1e-3, 12.0, 8.0)
    obs = Observation()
    for k in range(300):
        obs.reference_rad, obs.reference_velocity_rad_s = 0.2 * math.sin(k / 50), 4 * math.cos(k / 50)
        obs.reference_acceleration_rad_s2 = -80 * math.sin(k / 50)
        obs.angle_rad, obs.velocity_rad_s = 0.15 * math.sin(k / 47), 3 * math.cos(k / 47)
        expect = bare.update(obs.reference_rad, obs.reference_velocity_rad_s, obs.angle_rad, obs.velocity_rad_s,
                             ff.current_a(obs.reference_rad + cfg.com_angle_rad, obs.reference_acceleration_rad_s2))
        assert wrapped.update(obs) == expect


def test_user_controller_tracks_publishes_and_its_cost_is_the_control_tasks(user_file, tmp_path):
    out = tmp_path / "out"
    code = main(["run", "--quiet", "--strides", "1", "--controller", f"{user_file}:PdGravity", "--out", str(out)])
    assert code == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["tracking"]["truth"]["rms_deg"] < 3.0  # a plain PD + gravity: looser than the cascade, but it tracks
    assert s["controller"] == {"name": f"{user_file}:PdGravity", "class": "PdGravity",
                               "published": ["torque_nm", "error_deg"], "error": None}
    with (out / "telemetry.csv").open() as f:
        rows = list(csv.DictReader(f))
    running = [r for r in rows if r["supervisor_state_name"] == "RUN"]
    torques = {round(float(r["torque_nm"]), 3) for r in running}
    assert len(running) > 100 and len(torques) > 50  # the published value changes with the gait
    # what was logged is what the controller commanded: torque / (Kt N eta) == the current command
    for r in running[-20:]:
        assert float(r["current_cmd_a"]) == pytest.approx(float(r["torque_nm"]) / (0.078 * 28.0 * 0.855), rel=1e-5)
    r = _run(f"{user_file}:PdGravity")
    assert r.firmware.controller.resets == 1  # on entering RUN
    assert next(t for t in r.firmware.tasks if t.name == "control").cost == 2500


@pytest.mark.parametrize("cls, needle", [
    ("Raises", "controller Raises raised KeyError: 'missing' at {file}:"),
    ("ReturnsNan", "controller ReturnsNan.update returned nan (float) at {file}:"),
    ("ReturnsText", "controller ReturnsText.update returned '1 A' (str) at {file}:"),
])
def test_a_failing_controller_latches_the_safe_state_and_names_itself(user_file, cls, needle):
    r = _run(f"{user_file}:{cls}")
    sup = r.firmware.supervisor
    assert sup.state is SupervisorState.SAFE and sup.reason is FaultReason.CONTROLLER_ERROR
    assert needle.format(file=user_file) in r.firmware.controller_error
    assert sup.detail == r.firmware.controller_error
    line = int(r.firmware.controller_error.split(f"{user_file}:")[1].split(":")[0].split()[0])
    assert USER.splitlines()[line - 1].strip().startswith(("return", "def update"))
    # the period it failed in sent zero current; then the shipped safe state (graded): the phase short or the damper
    assert r.firmware.out.current_cmd_a == 0.0 and r.firmware.out.safe.behaviour in ("short", "damping")


def test_a_failing_controller_run_exits_non_zero_with_every_file_written(user_file, tmp_path, capsys):
    out = tmp_path / "out"
    code = main(["run", "--quiet", "--strides", "1", "--controller", f"{user_file}:Raises", "--out", str(out)])
    assert code == 1
    err = capsys.readouterr().err
    assert "controller Raises raised KeyError" in err and str(user_file) in err
    s = json.loads((out / "summary.json").read_text())
    assert s["faults"] == ["CONTROLLER_ERROR"] and "Raises" in s["controller"]["error"]
    for f in ("telemetry.bin", "telemetry.csv", "trace.pftrace", "report.md"):
        assert (out / f).stat().st_size > 0, f


def test_a_brake_command_object_reaches_the_motor(user_file):
    r = _run(f"{user_file}:Brakes")
    assert r.firmware.out.brake is True and r.firmware.out.current_cmd_a == 1.0
    assert r.firmware.supervisor.reason is FaultReason.NONE
    assert isinstance(MotorCommand(1.0), MotorCommand)


@pytest.mark.parametrize("spec, needle", [
    ("nope.py:X", "controller file 'nope.py' not found"),
    ("{file}:Missing", "has no class 'Missing'"),
    ("fancy", "is neither one of ['cascade', 'impedance', 'sysid'] nor FILE.py:CLASS"),
])
def test_bad_controller_names_are_one_line_and_exit_2(user_file, tmp_path, capsys, spec, needle):
    out = tmp_path / "out"
    code = main(["run", "--quiet", "--controller", spec.format(file=user_file), "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and needle in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_profile_names_the_controller_and_passes_its_table(user_file, tmp_path):
    profile = tmp_path / "fw.toml"
    base = (Path(__file__).parents[1] / "profiles" / "firmware.toml").read_text()
    profile.write_text(base + f'\n[controller]\nname = "{user_file.name}:PdGravity"\nk_nm_per_rad = 42.0\n')
    (tmp_path / user_file.name).write_text(USER)
    cfg = load_firmware_config(profile)
    ctl = build_controller(cfg.controller, cfg, cfg.controller_params)
    assert type(ctl).__name__ == "PdGravity" and ctl.k == 42.0
    with pytest.raises(ValueError, match="controller cascade takes no \\[controller\\] parameters"):
        build_controller("cascade", cfg, {"kp": 1})


@pytest.mark.parametrize(("doc", "heading"), [("README.md", "## Your own controller"),
                                              ("docs/controllers.md", "# Your own controller")])
def test_the_documented_example_controller_runs_as_written(tmp_path, doc, heading):
    """The README's 10-line controller and docs/controllers.md's complete one, each run as written."""
    text = (Path(__file__).parents[1] / doc).read_text(encoding="utf-8")
    section = text.split(heading, 1)[1]
    code = section.split("```python\n", 1)[1].split("```", 1)[0]
    (tmp_path / "my_controller.py").write_text(code, encoding="utf-8")
    r = _run(f"{tmp_path / 'my_controller.py'}:MyController", strides=1)
    assert r.firmware.supervisor.reason is FaultReason.NONE
    assert r.firmware.published_names == ("torque_nm", "error_deg")
    from host_tools.reports.report import summarise

    assert summarise(r)["tracking"]["truth"]["rms_deg"] < 3.0
