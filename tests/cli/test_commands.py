"""``skt``'s parser imports only the module of the command that runs: an import of a mesh
pays for neither PyTorch nor the evaluation's modules (each ``skt`` run is a process of its
own, so what it imports is paid on every run)."""

import json
import subprocess
import sys

from skt_lib.cli.main import COMMANDS, build_parser

PROBE = """
import json, sys
from skt_lib.cli.main import build_parser
build_parser({command!r})
print(json.dumps(sorted(m for m in ("torch", "skt_lib.cli.hang", "skt_lib.cli.predict", "skt_lib.cli.import_mesh",
                         "skt_lib.cli.import_support") if m in sys.modules)))
"""


def _imported(command) -> list[str]:
    out = subprocess.run([sys.executable, "-c", PROBE.format(command=command)], capture_output=True,
                         text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_an_import_command_imports_neither_torch_nor_the_other_commands():
    assert _imported("import-object") == ["skt_lib.cli.import_mesh"]
    # import-support builds on import-object's module, and on nothing that needs PyTorch
    assert _imported("import-support") == ["skt_lib.cli.import_mesh", "skt_lib.cli.import_support"]


def test_without_a_known_command_every_command_is_parsed():
    assert "torch" in _imported(None)  # predict and hang load models
    for command in (None, "bogus", "--help"):
        parser = build_parser(command)
        sub = next(a for a in parser._actions if a.dest == "command")
        assert list(sub.choices) == list(COMMANDS)
