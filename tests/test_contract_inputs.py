"""The input half of the commands' contract (host_tools/contract.py, docs/commands.md "The contract"): every file read
back (records, profiles, specs) is validated, and a bad one is one line naming the file and the key or byte offset,
exit 2 (never 1, which says "diverged", never a traceback); any exception a command lets through is one line with
the exit code of the table.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from contract_cases import one_line, pafp, split_record, with_header

from profiles import profile_path

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """A one-stride virtual run with --record."""
    out = tmp_path_factory.mktemp("rec") / "run"
    from host_tools.cli import main

    assert main(["run", "--strides", "1", "--quiet", "--no-plot", "--no-trace", "--record", "--out", str(out)]) == 0
    return out


# --- records (issue 35, case 2) ------------------------------------------------------------------------------------

@pytest.mark.parametrize("command", ["replay", "fit"])
def test_a_flipped_byte_in_the_header_is_a_damaged_record(command, recorded, tmp_path, capsys):
    """One flipped byte turned "cascade" into "casccde": a traceback and exit 1 ("diverged") before the checksum."""
    data = bytearray((recorded / "record.bin").read_bytes())
    at = data.index(b'"cascade"') + 5
    data[at] = ord("c")
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "record.bin").write_bytes(bytes(data))
    shutil.copy(recorded / "telemetry.csv", bad / "telemetry.csv")
    code, _, err = pafp(capsys, command, bad, "--out", tmp_path / "o")
    line = one_line(err)
    assert code == 2 and "header" in line and "damaged" in line and str(bad / "record.bin") in line
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(("edit", "needles"), [
    (lambda h: h["firmware"].update(controller="casccde"), ["'firmware'", "casccde"]),
    (lambda h: h["tasks"].__setitem__(2, "contrpl"), ["'tasks'", "contrpl"]),
    (lambda h: h.pop("firmware"), ["'firmware'", "missing"]),
    (lambda h: h["reference"].update(speed="brisk"), ["'reference.speed'", "brisk", "free"]),
    (lambda h: h["firmware"].pop("safety"), ["'firmware'", "safety"]),
    (lambda h: h.update(f_cpu_hz="fast"), ["'f_cpu_hz'", "an integer > 0"]),
], ids=["controller", "task", "no-firmware", "speed", "no-safety", "f_cpu"])
@pytest.mark.parametrize("version", [1, 2])
def test_a_header_naming_what_this_pafp_does_not_know_is_one_line(edit, needles, version, recorded, tmp_path, capsys):
    """Issue 35, case 2: a header that passes the checksum (hand-edited) or has none (format 1) but names an unknown
    controller, task or speed, or lacks a key: one line naming the key, exit 2."""
    bad = with_header(recorded / "record.bin", tmp_path / "bad", edit, version)
    code, _, err = pafp(capsys, "replay", bad, "--out", tmp_path / "o")
    line = one_line(err)
    assert code == 2 and str(bad / "record.bin") in line and all(n in line for n in needles), line


def test_a_record_of_format_1_still_replays(recorded, tmp_path, capsys):
    old = with_header(recorded / "record.bin", tmp_path / "old", lambda h: None, version=1)
    assert split_record((old / "record.bin").read_bytes())[0] == 1
    code, out, _ = pafp(capsys, "replay", old, "--out", tmp_path / "o")
    assert code == 0 and "byte-identical" in out


def test_a_record_of_a_newer_format_names_the_versions_read(recorded, tmp_path, capsys):
    data = bytearray((recorded / "record.bin").read_bytes())
    data[8:10] = (9).to_bytes(2, "little")
    (tmp_path / "record.bin").write_bytes(bytes(data))
    code, _, err = pafp(capsys, "replay", tmp_path, "--out", tmp_path / "o")
    assert code == 2 and "format version 9" in one_line(err) and "1, 2" in err


def test_a_missing_reference_csv_is_a_read_error(recorded, tmp_path, capsys):
    """Issue 35, case 6: a record naming a missing reference CSV said "cannot write /nonexistent.csv" (exit 74)."""
    bad = with_header(recorded / "record.bin", tmp_path / "bad",
                      lambda h: h["reference"].update(csv="/nonexistent.csv"))
    code, _, err = pafp(capsys, "replay", bad, "--out", tmp_path / "o")
    line = one_line(err)
    assert code == 2 and "'reference.csv'" in line and "/nonexistent.csv" in line and "write" not in line


def test_replay_of_something_that_is_not_a_file(tmp_path, capsys):
    """Issue 35, case 6: `replay /dev/null` said "not found"."""
    code, _, err = pafp(capsys, "replay", "/dev/null", "--out", tmp_path / "o")
    assert code == 2 and "/dev/null" in one_line(err) and "not a regular file" in err


# --- TOML files (issue 35, case 6) ---------------------------------------------------------------------------------

@pytest.fixture
def binary_toml(tmp_path):
    path = tmp_path / "packed.toml"
    path.write_bytes(b"\x1f\x8b\x08\x00gzip, not TOML")
    return path


@pytest.mark.parametrize("argv", [
    ["run", "--strides", "1", "--plant", "{f}"],
    ["run", "--strides", "1", "--battery", "{f}"],
    ["fit", "{run}", "--base", "{f}"],
])
def test_a_binary_toml_names_the_file(argv, binary_toml, recorded, tmp_path, capsys):
    """Issue 35, case 6: "'utf-8' codec can't decode byte 0x8b" without the file or the option."""
    words = [w.format(f=binary_toml, run=recorded) for w in argv]
    code, _, err = pafp(capsys, *words, "--out", tmp_path / "o")
    line = one_line(err)
    assert code == 2 and str(binary_toml) in line and "not a UTF-8 TOML file" in line and "codec" not in line


@pytest.mark.parametrize(("text", "where"), [
    ("[motor]\nkv = \n", "line 2, column 6"),
    ("[motor]\nkv = [1, 2,\n", "line 2 (the end of the file)"),
])
def test_malformed_toml_names_the_file_and_the_line(text, where, tmp_path, capsys):
    """Issue 35, case 6: "Invalid value (at end of document)" without the file or the line."""
    plant = tmp_path / "plant.toml"
    plant.write_text(text)
    code, _, err = pafp(capsys, "run", "--strides", "1", "--plant", plant, "--out", tmp_path / "o")
    line = one_line(err)
    assert code == 2 and str(plant) in line and where in line and "not valid TOML" in line


def test_toml_field_names_the_file_the_key_and_the_type():
    from profiles import toml_field

    assert toml_field({"a": 1}, "a", int, "x.toml", "spec") == 1
    assert toml_field({}, "a", int, "x.toml", "spec", default=3) == 3
    for doc, needle in (({"a": True}, "[t] a = True: expected an integer"), ({}, "key '[t] a' missing"),
                        ([1], "[t] is an array: expected a table")):
        with pytest.raises(ValueError, match=r"^spec x.toml: ") as e:
            toml_field(doc, "a", int, "x.toml", "spec", "[t]")
        assert needle in str(e.value)


def test_design_spec_ranges_are_the_real_limits(tmp_path):
    """Issue 35, case 6: the spec said 1..1000 teeth and 0..100000 N m/rad; the design loader allows 12..157 (2 mm
    pitch) and 0..2000."""
    from host_tools.studies.design_spec import load_design_spec

    spec = tmp_path / "d.toml"
    head = '[search]\nmotors = ["ak60_6"]\nbody_masses_kg = [20]\n'
    for belt, spring, needle in (("30/1001/2.0", "", "an int in 12..157"), ("30/140/2.0", 1e6, "[0, 2000]"),
                                 ("10/40/3.0", "", "an int in 16..104"), ("30/140/4.0", "", "one of 2, 3, 5, 8")):
        driver, driven, pitch = belt.split("/")
        text = head + f"[[belt]]\ndriver_teeth = {driver}\ndriven_teeth = {driven}\npitch_mm = {pitch}\n"
        if spring:
            text += f"[[spring]]\nstiffness_nm_per_rad = {spring}\n"
        spec.write_text(text)
        with pytest.raises(ValueError) as e:
            load_design_spec(spec)
        assert needle in str(e.value), str(e.value)
    doc = (ROOT / "docs" / "design.md").read_text()
    assert "12..157 at 2 mm" in doc and "0..2000 N m/rad" in doc


# --- fault:// URLs (issue 35, case 6) ------------------------------------------------------------------------------

@pytest.mark.parametrize(("query", "needle"), [
    ("fault=motor_replies_lost&at=1&phase=0.2", "at=1 and phase=0.2 both given"),
    ("fault=no_such_fault&at=1", "fault 'no_such_fault' unknown"),
    ("at=1", "fault=NAME is required"),
])
def test_a_refused_fault_url_is_named_once(query, needle, tmp_path, capsys):
    """Issue 35, case 6: "serial port '…' lost: cannot open: …" with the URL three times, and "one of … are required"
    when both at= and phase= were given."""
    url = f"fault://sim://ak60-6?{query}"
    code, _, err = pafp(capsys, "run", "--motor", url, "--imu", "sim://bno08x", "--duration", "1", "--out",
                        tmp_path / "o")
    line = one_line(err)
    assert code == 2 and line.count(url) == 1 and needle in line and "port lost" not in line.replace(url, ""), line


# --- the exit-code table -------------------------------------------------------------------------------------------

@pytest.mark.parametrize(("raised", "code", "needle"), [
    (ValueError("spec s.toml: x = 1 out of range"), 2, "pafp demo: spec s.toml: x = 1 out of range"),
    (OSError(28, "No space left on device", "o/x.json"), 74, "o/x.json: No space left on device"),
    (KeyError("firmware"), 3, "internal error: KeyError"),
    (GeneratorExit("odd"), 3, "internal error: GeneratorExit"),
    (KeyboardInterrupt(), 130, "pafp demo: interrupted"),
    (SystemExit("bye\nnow"), 1, "pafp demo: bye now"),
    (SystemExit(5), 5, None),
])
def test_any_exception_is_one_line_and_an_exit_code_of_the_table(raised, code, needle, capsys):
    import argparse

    from host_tools.contract import run_command

    def body(args):
        raise raised

    assert run_command("demo", body, argparse.Namespace()) == code
    err = capsys.readouterr().err
    if needle is None:
        assert err == ""
    else:
        assert needle in one_line(err)


def test_the_exit_table_is_the_one_documented():
    from host_tools.contract import EXIT_CODES

    doc = (ROOT / "docs" / "commands.md").read_text()
    assert sorted(EXIT_CODES) == [0, 1, 2, 3, 74]
    for code in EXIT_CODES:
        assert f"| {code} |" in doc


def test_every_command_runs_under_the_contract(monkeypatch, tmp_path, capsys):
    """cli.main hands every command to contract.run_command: none can bypass it."""
    import host_tools.contract as contract

    seen = []
    monkeypatch.setattr(contract, "run_command", lambda name, body, args: seen.append(name) or 0)
    plant = profile_path("plant_ak60_6.toml")
    assert pafp(capsys, "run", "--plant", plant, "--out", tmp_path / "o")[0] == 0
    assert pafp(capsys, "rta", "x.toml")[0] == 0
    assert seen == ["run", "rta"]
