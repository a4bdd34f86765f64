"""tools.mutation: merging a run into the reports keeps the other modules' entries and drops
those of modules no longer in the repository."""

import json

from tools import mutation


def _result(killed: int, survivors: list[str]) -> dict:
    return {"killed": killed, "survived": len(survivors), "timeout": 0,
            "score": round(killed / (killed + len(survivors)), 4), "equivalent": 0, "no_tests": 0,
            "other": {}, "seconds": 1.0, "tests": ["tests/test_x.py"],
            "_survivors": survivors, "_equivalent": []}


def test_merge_replaces_keeps_and_drops_modules_by_their_files(tmp_path):
    root, out = tmp_path / "repo", tmp_path / "reports"
    for m in ("pkg/kept.py", "pkg/rerun.py"):
        (root / m).parent.mkdir(parents=True, exist_ok=True)
        (root / m).write_text("")
    # an earlier run: three modules, one of which (gone.py) has since been deleted
    mutation.write_reports({m: _result(3, [f"{m}.x_f__mutmut_1"])
                            for m in ("pkg/kept.py", "pkg/rerun.py", "pkg/gone.py")}, out, root)
    assert set(json.loads((out / "mutation.json").read_text())) == {"pkg/kept.py", "pkg/rerun.py"}
    mutation.write_reports({"pkg/rerun.py": _result(9, [])}, out, root)
    summary = json.loads((out / "mutation.json").read_text())
    assert list(summary) == ["pkg/kept.py", "pkg/rerun.py"]
    assert summary["pkg/kept.py"]["killed"] == 3 and summary["pkg/rerun.py"]["killed"] == 9
    assert "_survivors" not in summary["pkg/rerun.py"]
    md = (out / "mutation.md").read_text()
    assert md.count("\n## `") == 2 and "gone.py" not in md
    assert "`pkg/kept.py.x_f__mutmut_1`" in md  # the kept module's section, as it was
    # a report written before the module was deleted: its entry goes at the next merge
    (root / "pkg/kept.py").unlink()
    mutation.write_reports({"pkg/rerun.py": _result(9, [])}, out, root)
    assert list(json.loads((out / "mutation.json").read_text())) == ["pkg/rerun.py"]
    assert "kept.py" not in (out / "mutation.md").read_text()
