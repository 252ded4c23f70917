"""`pafp rta`: table, exact JSON, emulation, and one-line errors with exit code 2."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from host_tools.cli import main

DAVIS = str(Path(__file__).resolve().parents[1] / "profiles" / "tasksets" / "davis2007.toml")


def _rta(capsys, *args):
    code = main(["rta", *args])
    out, err = capsys.readouterr()
    return code, out, err


def test_json_is_exactly_the_documented_shape(capsys):
    code, out, err = _rta(capsys, DAVIS, "--json")
    assert code == 1 and err == ""  # C can miss its deadline
    doc = json.loads(out)
    assert list(doc) == ["tasks"]
    assert doc["tasks"] == [
        {"name": "A", "period": 2500, "deadline": 2500, "cost": 1000, "bound": 2000, "schedulable": True},
        {"name": "B", "period": 3500, "deadline": 3250, "cost": 1000, "bound": 3000, "schedulable": True},
        {"name": "C", "period": 3500, "deadline": 3250, "cost": 1000, "bound": 3500, "schedulable": False},
    ]


def test_simulate_adds_observed(capsys):
    code, out, _ = _rta(capsys, DAVIS, "--simulate", "--json")
    assert code == 1
    observed = {t["name"]: t["observed"] for t in json.loads(out)["tasks"]}
    assert observed == {"A": 1999, "B": 2999, "C": 3500}


def test_table_lists_every_task(capsys):
    code, out, _ = _rta(capsys, DAVIS, "--simulate")
    assert code == 1
    lines = out.splitlines()
    assert "bound" in lines[1] and "observed" in lines[1]
    row_c = next(line for line in lines if line.split()[:1] == ["C"])
    assert row_c.split() == ["C", "3", "3500", "3250", "1000", "3500", "NO", "3500"]
    assert "CAPPED" not in out


def test_units_are_converted_back_and_capping_is_said(tmp_path, capsys):
    p = tmp_path / "ms.toml"
    p.write_text('unit = "ms"\nf_cpu_hz = 1_000_000\n'
                 '[[task]]\nname = "a"\npriority = 1\nperiod = 1\ncost = 0.25\n'
                 '[[task]]\nname = "b"\npriority = 2\nperiod = 7.5\ncost = 1.5\n'
                 '[[interrupt]]\nname = "tick"\nperiod = 1\ncost = 0.005\n')
    code, out, _ = _rta(capsys, str(p), "--json", "--simulate", "--max-jobs", "50")
    assert code == 1  # a's bound (1.76 ms) exceeds its 1 ms deadline
    a, b = json.loads(out)["tasks"]
    assert a["period"] == 1 and a["cost"] == 0.25 and b["period"] == 7.5
    assert a["bound"] == 1.76  # 1.5 ms blocking + 0.25 ms + two 5 µs ticks, in ms
    code, out, _ = _rta(capsys, str(p), "--simulate", "--max-jobs", "10")
    assert "CAPPED" in out


@pytest.mark.parametrize("content,needle", [
    (None, "nope.toml"),
    ('unit = "us\n', "not valid TOML"),
    ('unit="us"\nf_cpu_hz=1000000\n[[task]]\nname="x"\npriority=1\nperiod=-5\ncost=1\n', "period"),
    ('unit="us"\nf_cpu_hz=1000000\n[[task]]\nname="x"\npriority=1\nperiod=5\ncost=1\n'
     '[[task]]\nname="y"\npriority=1\nperiod=5\ncost=1\n', "priority 1"),
    ('unit="furlongs"\nf_cpu_hz=1000000\n', "furlongs"),
    ('unit="us"\nf_cpu_hz=1000000\n[[task]]\nname="x"\npriority=1\nperiod=5\ncost=1\nprio=3\n', "prio"),
    ('unit="us"\nf_cpu_hz=1000000\n', "no [[task]] table"),
])
def test_bad_input_is_one_line_on_stderr_and_exit_2(tmp_path, capsys, content, needle):
    path = tmp_path / "nope.toml"
    if content is not None:
        path.write_text(content)
    code, out, err = _rta(capsys, str(path))
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1
    assert needle in err
    if needle == "period":
        assert "-5" in err


def _primes(count: int) -> list[int]:
    out: list[int] = []
    n = 1000
    while len(out) < count:
        n += 1
        if all(n % p for p in range(2, int(n**0.5) + 1)):
            out.append(n)
    return out


def test_simulate_on_200_coprime_periods_is_capped_not_an_overflow(tmp_path, capsys):
    """The hyperperiod has ~650 digits: too large for a float, the cap applies and the note prints it short."""
    lines = ['unit = "us"', "f_cpu_hz = 1000000"]
    for k, p in enumerate(_primes(200)):
        lines += ["[[task]]", f'name = "t{k}"', f"priority = {k + 1}", f"period = {p * 100}", "cost = 1"]
    path = tmp_path / "coprime.toml"
    path.write_text("\n".join(lines) + "\n")
    code, out, err = _rta(capsys, str(path), "--simulate", "--max-jobs", "500")
    assert code == 0 and err == ""
    note = out.strip().splitlines()[-1]
    assert "CAPPED at --max-jobs=500" in note and re.search(r"hyperperiod is \d\.\d{3}e\d{3} us", note)
    assert len(note) < 200
