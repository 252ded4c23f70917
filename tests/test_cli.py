"""The `pafp` command line: every subcommand is listed, unfinished ones refuse loudly."""

import subprocess
import sys

from host_tools.cli import COMMANDS, main


def test_help_lists_every_subcommand(capsys):
    try:
        main(["--help"])
    except SystemExit as e:
        assert e.code == 0
    out = capsys.readouterr().out
    for name in COMMANDS:
        assert name in out


def test_python_m_host_tools_runs():
    r = subprocess.run([sys.executable, "-m", "host_tools", "--help"], capture_output=True, text=True)
    assert r.returncode == 0
    assert "decode" in r.stdout


def test_version_names_the_distribution_and_the_build(capsys):
    from host_tools.build_info import describe, version

    try:
        main(["--version"])
    except SystemExit as e:
        assert e.code == 0
    assert capsys.readouterr().out == f"pafp {version()} ({describe()})\n"
