"""The commands' contract under fuzzing (docs/commands.md, "The contract"): the TOML of every spec and profile kind
with random structure and types, and random bytes flipped in record.bin and in wire and telemetry captures. Whatever
the input, no exception escapes `pafp`, the exit is 0, 1, 2 or 74, and a refusal is one line on stderr.

Each example runs `pafp` in this process (host_tools.cli.main) with an --out that is an existing *file*, so an
input that passes every check is still refused (exit 2) before any long work: the property is about the checks.
The default Hypothesis profile draws a few examples per kind; `make fuzz` (the fuzz profile) ten times as many.
"""

from __future__ import annotations

import copy
import shutil
from pathlib import Path

import pytest
import tomlkit
from contract_cases import ALLOWED_EXITS, pafp
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from profiles import profile_path, read_toml

EXAMPLES = max(4, settings.default.max_examples // 12)
"""Examples per kind: 8 in the default profile (the whole file runs in about a minute), 83 under `make fuzz`."""
HEALTH = [*settings.default.suppress_health_check, HealthCheck.function_scoped_fixture]  # capsys is read each time

scalars = st.one_of(st.integers(-(2**63), 2**63 - 1), st.integers(-3, 300), st.booleans(),
                    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=8),
                    st.sampled_from(["", "cascade", "walk", "ak60_6", "../x.toml", "free", "uart", "none", "auto"]))
values = st.recursive(scalars, lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=6), inner,
                                                                                          max_size=3), max_leaves=6)


def _paths(doc: object, prefix: tuple = ()) -> list[tuple]:
    """Every place in a parsed TOML document (dict keys and list indices), the root included."""
    out = [prefix]
    if isinstance(doc, dict):
        for k, v in doc.items():
            out += _paths(v, (*prefix, k))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            out += _paths(v, (*prefix, i))
    return out


def _mutate(data, doc: dict) -> dict:
    """doc with one to three random changes of structure or type (a value replaced, a key removed or added, a table
    made an array of tables or the reverse)."""
    doc = copy.deepcopy(doc)
    for _ in range(data.draw(st.integers(1, 3))):
        where = data.draw(st.sampled_from(_paths(doc)))
        if not where:
            doc.setdefault(data.draw(st.text(max_size=6)), data.draw(values))
            continue
        parent = doc
        for step in where[:-1]:
            parent = parent[step]
        key, old = where[-1], parent[where[-1]]
        op = data.draw(st.sampled_from(["replace", "delete", "wrap", "unwrap", "add"]))
        if op == "delete" and isinstance(parent, dict):
            del parent[key]
        elif op == "wrap":
            parent[key] = [old]
        elif op == "unwrap" and isinstance(old, list) and old:
            parent[key] = old[0]
        elif op == "add" and isinstance(old, dict):
            old[data.draw(st.text(min_size=1, max_size=6))] = data.draw(values)
        else:
            parent[key] = data.draw(values)
    return doc


def _toml_text(data, seed: dict) -> bytes:
    """A mutated seed as TOML, now and then with a byte flipped (not UTF-8, not TOML)."""
    try:
        text = tomlkit.dumps(_mutate(data, seed)).encode("utf-8")
    except Exception:  # noqa: BLE001 - a document tomlkit cannot write (e.g. a lone surrogate): not an example
        assume(False)
    if text and data.draw(st.integers(0, 4)) == 0:
        at = data.draw(st.integers(0, len(text) - 1))
        text = text[:at] + bytes([text[at] ^ data.draw(st.integers(1, 255))]) + text[at + 1:]
    return text


def _check(capsys, *argv: object) -> None:
    code, _, err = pafp(capsys, *argv)
    assert "Traceback" not in err, err
    assert code in ALLOWED_EXITS, (code, err)
    if code != 0:
        assert len([line for line in err.splitlines() if line.strip()]) == 1, err


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    """A directory with the seeds of every kind (relative references made absolute), a file to point --out at, and a
    one-stride recorded run with its wire capture."""
    root = tmp_path_factory.mktemp("fuzz")
    (root / "out_is_a_file").write_text("")
    firmware = profile_path("firmware.toml")
    faults = read_toml(profile_path("faults/default.toml"), "fault spec")
    faults["campaign"].update(criteria=str(profile_path("faults/criteria.toml")), onsets=[0.25], durations_s=[0.05],
                              links=["uart"])
    faults["fault"], faults["scenario"] = faults["fault"][:2], faults["scenario"][:1]
    design = read_toml(profile_path("designs/adult.toml"), "design spec")
    design["search"].update(motors=["ak60_6"], body_masses_kg=[20], speeds=["free"], strides=1)
    design["belt"], design["spring"] = design["belt"][:1], design.get("spring", [{}])[:1]
    sweep = read_toml(profile_path("sweeps/baud_gains.toml"), "sweep spec")
    sweep["base"]["profile"] = str(firmware)
    seeds = {"firmware": read_toml(firmware, "firmware profile"),
             "design_profile": read_toml(profile_path("designs/ak60_6_report.toml"), "design profile"),
             "plant": read_toml(profile_path("plant_ak60_6.toml"), "plant profile"),
             "battery": read_toml(profile_path("batteries/molicel_p42a_6s1p.toml"), "battery profile"),
             "motor": read_toml(profile_path("motors/ak60_6.toml"), "motor profile"),
             "criteria": read_toml(profile_path("faults/criteria.toml"), "criteria"),
             "taskset": read_toml(profile_path("tasksets/davis2007.toml"), "task set"),
             "fault_spec": faults, "design_spec": design, "sweep_spec": sweep}
    from host_tools.cli import main

    run = root / "run"
    assert main(["run", "--strides", "1", "--quiet", "--no-plot", "--no-trace", "--record", "--capture",
                 str(root / "capture"), "--out", str(run)]) == 0
    return root, seeds


def _argv(kind: str, f: Path, root: Path, seeds: dict) -> list[object]:
    """The command that reads a file of this kind (others it needs written from their seeds)."""
    out = root / "out_is_a_file"
    run = ["run", "--strides", "1", "--quiet", "--no-plot", "--no-trace", "--out", out]
    if kind in ("firmware", "design_profile"):
        return [*run, "--profile", f]
    if kind in ("plant", "battery"):
        return [*run, f"--{kind}", f]
    if kind == "fit_base":
        return ["fit", root / "no-such-run", "--base", f, "--out", out]
    if kind == "taskset":
        return ["rta", f]
    if kind == "criteria":
        spec = copy.deepcopy(seeds["fault_spec"])
        spec["campaign"]["criteria"] = str(f)
        (root / "spec.toml").write_text(tomlkit.dumps(spec))
        return ["faults", root / "spec.toml", "--out", out]
    if kind == "motor":
        spec = copy.deepcopy(seeds["design_spec"])
        spec["search"]["motors"] = [str(f)]
        (root / "spec.toml").write_text(tomlkit.dumps(spec))
        return ["design", root / "spec.toml", "--out", out]
    return [kind.removesuffix("_spec"), f, "--out", out]


KINDS = ["firmware", "design_profile", "plant", "battery", "motor", "fit_base", "criteria", "taskset", "fault_spec",
         "design_spec", "sweep_spec"]


@pytest.mark.parametrize("kind", KINDS)
@settings(max_examples=EXAMPLES, suppress_health_check=HEALTH)
@given(data=st.data())
def test_any_toml_of_any_kind_is_a_clean_exit(kind, data, work, capsys):
    root, seeds = work
    seed = seeds["plant" if kind == "fit_base" else kind]
    f = root / f"{kind}.toml"
    f.write_bytes(_toml_text(data, seed))
    _check(capsys, *_argv(kind, f, root, seeds))


def _flipped(data, raw: bytes, header_bytes: int) -> bytes:
    """raw with one to four bytes flipped: anywhere, or within its first header_bytes."""
    b = bytearray(raw)
    for _ in range(data.draw(st.integers(1, 4))):
        end = min(len(b), header_bytes) if data.draw(st.booleans()) else len(b)
        at = data.draw(st.integers(0, end - 1))
        b[at] ^= data.draw(st.integers(1, 255))
    if data.draw(st.integers(0, 5)) == 0:  # and now and then cut short
        del b[data.draw(st.integers(0, len(b) - 1)):]
    return bytes(b)


@settings(max_examples=max(3, EXAMPLES // 2), suppress_health_check=HEALTH)
@given(data=st.data())
def test_flipped_bytes_in_a_record_are_a_clean_exit(data, work, tmp_path_factory, capsys):
    root, _ = work
    bad = tmp_path_factory.mktemp("bad")
    shutil.copy(root / "run" / "telemetry.csv", bad / "telemetry.csv")
    (bad / "record.bin").write_bytes(_flipped(data, (root / "run" / "record.bin").read_bytes(), 4096))
    command = data.draw(st.sampled_from(["replay", "fit"]))
    out = root / "out_is_a_file" if command == "fit" else bad / "replayed"
    _check(capsys, command, bad, "--out", out)


CAPTURES = [("motor.tx.bin", ["decode", "--protocol", "vesc", "--direction", "to-motor"]),
            ("motor.rx.bin", ["decode", "--protocol", "vesc"]), ("imu.rx.bin", ["decode", "--protocol", "rvc"]),
            ("telemetry.tx.bin", ["decode", "--protocol", "telemetry"]), ("telemetry.tx.bin", ["monitor"])]


@settings(max_examples=EXAMPLES, suppress_health_check=HEALTH)
@given(data=st.data(), capture=st.sampled_from(CAPTURES))
def test_flipped_bytes_in_a_capture_are_a_clean_exit(data, capture, work, tmp_path_factory, capsys):
    root, _ = work
    name, argv = capture
    f = tmp_path_factory.mktemp("cap") / name
    raw = (root / "capture" / name).read_bytes()[:20000]
    f.write_bytes(_flipped(data, raw, 256) if raw else raw)
    _check(capsys, *argv, f)
