"""A bad option, or one given where it has no effect, is one line naming the option, the value and the range.

No usage block first, exit 2, nothing written (each case points --out, where it has one, at a directory that must
stay absent).
"""

from pathlib import Path

import pytest

from host_tools.cli import main

DAVIS = Path(__file__).parents[1] / "profiles" / "tasksets" / "davis2007.toml"
SPEC = Path(__file__).parents[1] / "profiles" / "sweeps" / "robustness.toml"


def _pafp(capsys, *argv: str) -> tuple[int, str, str]:
    try:
        code = main(list(argv))
    except SystemExit as e:  # argparse
        code = e.code
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize(("argv", "needles"), [
    (["run", "--seed", "-1"], ["--seed", "-1", "an integer >= 0"]),
    (["run", "--plant-seed", "-5", "--strides", "1"], ["plant seed -5", "0..4294967295"]),
    (["tune", "--seed", "-1"], ["--seed", "-1", "an integer >= 0"]),
    (["bench", "tracking", "--seed", "-1"], ["--seed", "-1", "an integer >= 0"]),
    (["emulate", "imu", "--pty", "--seed", "-1"], ["--seed", "-1", "an integer >= 0"]),
    (["run", "--strides", "abc"], ["--strides", "'abc'", "int"]),
    (["run", "--scenario", "stairs"], ["--scenario", "'stairs'", "'suspended', 'walk'"]),
    (["bench"], ["test"]),
    # ignored options are refused, naming the run they belong to
    (["run", "--duration", "5"], ["--duration 5", "virtual bench", "--strides N", "1..10000"]),
    (["run", "--motor", "sim://ak60-6", "--imu", "sim://bno08x", "--strides", "3"],
     ["--strides 3", "serial mode", "--duration S", "> 0"]),
    (["run", "--body-mass", "70"], ["--body-mass 70", "--scenario walk"]),
    (["run", "--moment", "m.csv", "--strides", "1"], ["--moment m.csv", "--scenario walk"]),
    (["run", "--motor", "sim://ak60-6", "--imu", "sim://bno08x", "--duration", "nan"],
     ["--duration", "nan", "(0, inf) s"]),
    (["run", "--motor", "sim://ak60-6", "--imu", "sim://bno08x", "--duration", "-1"], ["--duration", "-1", "(0, inf)"]),
    (["monitor", "x.bin", "--baud", "0"], ["--baud", "0", "[1, 20000000]"]),
    (["monitor", "x.bin", "--duration", "-1"], ["--duration", "-1", "(0, inf) s"]),
    (["monitor", "x.bin", "--duration", "nan"], ["--duration", "nan", "(0, inf) s"]),
    (["monitor", "x.bin", "--duration", "inf"], ["--duration", "inf", "(0, inf) s"]),
    (["sweep", str(SPEC), "--scheduler", "nosuch.json"], ["--scheduler 'nosuch.json'", "no such file",
                                                           "tcp://HOST:PORT"]),
    (["sweep", str(SPEC), "--scheduler", "localhost"], ["--scheduler 'localhost'", "HOST:PORT"]),
    (["tune", "--scheduler", "nosuch.json"], ["--scheduler 'nosuch.json'", "no such file"]),
    (["run", "--profile", "/dev/null"], ["/dev/null is empty", "[control]", "profiles/firmware.toml"]),
])
def test_a_bad_option_is_one_line_naming_it_its_value_and_range(tmp_path, capsys, argv, needles):
    out = tmp_path / "never"
    if argv[0] in ("run", "bench", "tune", "sweep"):
        argv = [*argv, "--out", str(out)]
    code, stdout, err = _pafp(capsys, *argv)
    assert code == 2, (code, err)
    assert "usage:" not in err and len(err.strip().splitlines()) == 1, err
    for needle in needles:
        assert needle in err, (needle, err)
    assert not out.exists()


def test_an_infinite_period_in_a_task_set_names_the_task_and_the_range(tmp_path, capsys):
    for key, value, rule in (("period", "inf", "> 0"), ("period", "nan", "> 0"), ("cost", "-inf", ">= 0"),
                             ("jitter", "inf", ">= 0")):
        text = DAVIS.read_text(encoding="utf-8").replace(f"{key} = ", f"{key} = {value} #", 1)
        path = tmp_path / "ts.toml"
        path.write_text(text, encoding="utf-8")
        code, stdout, err = _pafp(capsys, "rta", str(path))
        assert code == 2 and len(err.strip().splitlines()) == 1, err
        assert f"task 'A': {key} must be a finite number {rule} us, got {value}" in err, err
