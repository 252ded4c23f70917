"""The gearbox backlash is a plant-profile key: a plant file sets the bench's, --plant-seed draws it, --ideal clears
it."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

from hal.virtual.plant import load_plant_params
from hal.virtual.plant.draw import draw_plant
from host_tools.runner import RunConfig
from host_tools.serial_mode.served_plant import served_plant

ROOT = Path(__file__).resolve().parents[1]
HANDMADE = ROOT / "tests" / "data" / "plant_handmade.toml"


def _without_key(tmp_path: Path) -> Path:
    text = (ROOT / "profiles" / "plant_ak60_6.toml").read_text()
    text, n = re.subn(r"^backlash_deg\s*=[^\n]*\n", "", text, count=1, flags=re.M)
    assert n == 1
    path = tmp_path / "nokey.toml"
    path.write_text(text)
    return path


def test_packaged_plant_has_the_makers_backlash():
    assert load_plant_params().backlash_deg == 0.55


def test_plant_file_sets_the_benchs_backlash(tmp_path):
    options, record = RunConfig(plant_file=HANDMADE).bench_setup()
    assert options["backlash_rad"] == pytest.approx(math.radians(1.5))
    assert record["plant"]["backlash_deg"] == pytest.approx(1.5)
    # the serial-mode emulator builds its bench the same way
    emu = served_plant(seed=0, plant_file=HANDMADE).options
    assert emu["backlash_rad"] == pytest.approx(math.radians(1.5))
    # switched off, there is none whatever the plant file says
    ideal, _ = RunConfig(plant_file=HANDMADE, ideal=("gearbox_backlash",)).bench_setup()
    assert ideal["backlash_rad"] == 0.0


def test_absent_key_is_the_imperfections_figure(tmp_path):
    path = _without_key(tmp_path)
    assert load_plant_params(path).backlash_deg is None
    options, _ = RunConfig(plant_file=path).bench_setup()
    assert options["backlash_rad"] == pytest.approx(math.radians(0.55))  # bench_imperfections.toml's


def test_bad_backlash_is_named(tmp_path):
    text = HANDMADE.read_text().replace("backlash_deg = 1.5 ", "backlash_deg = 12.0 ")
    (tmp_path / "bad.toml").write_text(text)
    with pytest.raises(ValueError, match=r"transmission\.backlash_deg = 12\.0 is outside the allowed range"):
        load_plant_params(tmp_path / "bad.toml")


def test_plant_seed_draws_the_backlash_within_its_tolerance(tmp_path):
    nominal = load_plant_params()
    drawn = [draw_plant(nominal, s).backlash_deg for s in range(20)]
    assert all(0.275 <= b <= 0.825 for b in drawn) and len(set(drawn)) == 20
    assert draw_plant(nominal, 7) == draw_plant(nominal, 7)
    # the hand-made plant's 1.5 deg is drawn around, not replaced
    hm = load_plant_params(HANDMADE)
    assert 0.75 <= draw_plant(hm, 7).backlash_deg <= 2.25
    # a profile without the key keeps the imperfection's figure: nothing is drawn for it
    assert draw_plant(load_plant_params(_without_key(tmp_path)), 7).backlash_deg is None


def test_the_handmade_plant_is_the_issues():
    hm, nominal = load_plant_params(HANDMADE), load_plant_params()
    assert hm.output_inertia_kg_m2 / nominal.output_inertia_kg_m2 == pytest.approx(1.30, abs=1e-4)
    assert hm.coulomb_friction_nm == pytest.approx(2.5 * nominal.coulomb_friction_nm)
    assert hm.backlash_deg == 1.5


def test_fit_writes_its_backlash_verdict_into_the_key(tmp_path):
    """The fitted profile carries backlash_deg: replaced in a base that has it, added to one that has not."""
    import numpy as np

    from host_tools.calibration.fit_model import base_values
    from host_tools.calibration.fit_report import profile_text
    from host_tools.calibration.plant_fit import FitResult

    base = load_plant_params()
    start = base_values(base)
    assert start["backlash_deg"] == 0.55
    values = {**start, "backlash_deg": 1.4}
    r = FitResult(("backlash_deg",), values, start, {"backlash_deg": 0.2}, {"backlash_deg": 1.0},
                  {"backlash_deg": True}, np.eye(1), {}, 1, 0.0, 0.0, (0.0, 1.0), "", {})
    for path in (ROOT / "profiles" / "plant_ak60_6.toml", _without_key(tmp_path)):
        text = profile_text(path.read_text(), load_plant_params(path), r, "runs/x")
        (tmp_path / "out.toml").write_text(text)
        assert load_plant_params(tmp_path / "out.toml").backlash_deg == 1.4
        assert re.search(r"^backlash_deg = 1\.4  # fitted from runs/x: backlash_deg 1\.4 ± 0\.2 \(95 %\)", text, re.M)
    not_ident = FitResult(("backlash_deg",), values, start, {"backlash_deg": 3.0}, {"backlash_deg": 1.0},
                          {"backlash_deg": False}, np.eye(1), {}, 1, 0.0, 0.0, (0.0, 1.0), "", {})
    text = profile_text((ROOT / "profiles" / "plant_ak60_6.toml").read_text(), base, not_ident, "runs/x")
    assert re.search(r"^backlash_deg = 0\.55  # fitted from runs/x: backlash_deg not identifiable \(kept\)", text, re.M)


@pytest.mark.parametrize("params", ["backlash_deg", "rotor_accel_scale", "backlash_deg,rotor_accel_scale"])
def test_the_profiled_ones_alone_are_refused(tmp_path, capsys, params):
    from host_tools.cli import main

    assert main(["fit", str(tmp_path), "--params", params]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "are profiled with other parameters fitted" in err[0]
