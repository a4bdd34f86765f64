"""``skt``'s streams are its interface: nothing but the result on stdout, nothing but one
``ERROR:`` line on stderr — PyBullet's import banner goes nowhere (stderr with --debug)."""

import subprocess
import sys


def _skt(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "skt_lib.cli.main", *args],
                          capture_output=True, text=True, timeout=120)


def test_an_error_is_one_line_on_stderr_and_nothing_on_stdout(tmp_path):
    proc = _skt("import-support", str(tmp_path / "missing.stl"))
    assert proc.returncode == 2
    assert proc.stdout == ""
    assert proc.stderr.splitlines() == [f"ERROR: {tmp_path / 'missing.stl'}: no such mesh"]


def test_debug_shows_the_banner_on_stderr_never_stdout(tmp_path):
    proc = _skt("--debug", "import-support", str(tmp_path / "missing.stl"))
    assert proc.returncode == 2
    assert proc.stdout == ""
    assert "pybullet build time" in proc.stderr
