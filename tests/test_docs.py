"""The documentation is checked against the code: links resolve, every params key and every
table column is documented, the front page stays short, and its run figures are the ones
the committed reports give (``tools/docs_results.py``)."""

import importlib
import json
import re
import shutil
from pathlib import Path

import pytest
import yaml
from pydantic import BaseModel, create_model

import skt_lib.schemas
from skt_lib.config import CommonParams
from skt_lib.config.params_file import Params
from skt_lib.io import TableSchema
from tools import docs_results

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DOCS = sorted((ROOT / "docs").glob("*.md"))
PAGES = [README, *DOCS]

LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*$", re.M)
FENCE = re.compile(r"^\s*```.*?^\s*```", re.M | re.S)


def _prose(text: str) -> str:
    """``text`` without fenced code blocks (a ``# comment`` there is no heading)."""
    return FENCE.sub("", text)


def _slug(heading: str) -> str:
    """GitHub's anchor for a heading: link text kept, lower case, punctuation dropped."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading).lower()
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def anchors(text: str) -> set[str]:
    seen: dict[str, int] = {}
    out = set()
    for _, title in HEADING.findall(_prose(text)):
        slug = _slug(title)
        out.add(slug if slug not in seen else f"{slug}-{seen[slug]}")
        seen[slug] = seen.get(slug, 0) + 1
    return out


def links(text: str) -> list[str]:
    return LINK.findall(_prose(text))


def section(text: str, marker: str) -> str:
    """The section whose heading contains ``marker``, up to the next heading of its level or
    above; "" when no heading has it. Fails when several do."""
    text = _prose(text)
    found = [m for m in HEADING.finditer(text) if marker in m.group(2)]
    assert len(found) <= 1, f"{len(found)} headings contain {marker!r}"
    if not found:
        return ""
    level = len(found[0].group(1))
    rest = text[found[0].end():]
    nxt = next((m for m in HEADING.finditer(rest) if len(m.group(1)) <= level), None)
    return rest[: nxt.start()] if nxt else rest


def param_keys(model: type[BaseModel], prefix: str = "") -> list[str]:
    """Dotted keys of every leaf field of ``model``, nested sections walked."""
    keys = []
    for name, field in model.model_fields.items():
        key = f"{prefix}{name}"
        if isinstance(field.annotation, type) and issubclass(field.annotation, BaseModel):
            keys += param_keys(field.annotation, key + ".")
        else:
            keys.append(key)
    return keys


def documented_params(page: str) -> dict[str, str]:
    """``section.key`` -> the value cell of its row, from the table of the section's
    ``## `section``` part of the page (a row elsewhere does not count)."""
    rows = {}
    for sec in Params.model_fields:
        for key, value in re.findall(r"^\| `([^`]+)` \| (.*?) \|", section(page, f"`{sec}`"), re.M):
            if key.startswith(sec + "."):
                rows[key] = value
    return rows


def undocumented(model: type[BaseModel], page: str) -> list[str]:
    rows = documented_params(page)
    return [k for k in param_keys(model) if k not in rows]


def _lookup(data: dict, key: str):
    for part in key.split("."):
        data = data[part]
    return data


# --- links ------------------------------------------------------------------------------

@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_relative_links_resolve(page):
    text = page.read_text()
    bad = []
    for target in links(text):
        if re.match(r"[a-z]+:", target):  # http(s), mailto
            continue
        path, _, fragment = target.partition("#")
        dest = (page.parent / path).resolve() if path else page
        if not dest.exists():
            bad.append(f"{target}: no such file")
        elif fragment and dest.suffix == ".md" and fragment not in anchors(dest.read_text()):
            bad.append(f"{target}: no heading with that anchor in {dest.name}")
    assert not bad, f"{page.relative_to(ROOT)}: broken links:\n" + "\n".join(bad)


def test_readme_links_every_docs_page():
    targets = {(ROOT / t.partition("#")[0]).resolve() for t in links(README.read_text())}
    missing = [p.name for p in DOCS if p.resolve() not in targets]
    assert DOCS and not missing, f"README.md does not link to docs/{missing}"


def test_anchor_slugs_follow_github():
    assert _slug("Keypoints (`contact_sim`, `rotation_extraction`)") == \
        "keypoints-contact_sim-rotation_extraction"
    assert _slug("Bad input ([`tests/x.py`](../tests/x.py), one row)") == \
        "bad-input-testsxpy-one-row"
    assert anchors("# A\n## A\n```\n# not a heading\n```\n") == {"a", "a-1"}


# --- parameters -------------------------------------------------------------------------

def test_every_params_key_documented_with_its_committed_value():
    page = (ROOT / "docs" / "parameters.md").read_text()
    rows = documented_params(page)
    assert not undocumented(Params, page), "keys missing from docs/parameters.md"
    committed = yaml.safe_load((ROOT / "params.yaml").read_text())
    wrong = []
    for key in param_keys(Params):
        value = yaml.safe_load(rows[key].replace("`", ""))
        if value != _lookup(committed, key):
            wrong.append(f"{key}: page says {rows[key]}, params.yaml has "
                         f"{_lookup(committed, key)!r}")
    assert not wrong, "docs/parameters.md disagrees with params.yaml:\n" + "\n".join(wrong)
    extra = set(rows) - set(param_keys(Params))
    assert not extra, f"docs/parameters.md documents keys the models do not have: {sorted(extra)}"


def test_params_check_notices_an_undocumented_key():
    page = (ROOT / "docs" / "parameters.md").read_text()
    sede = create_model("CommonParams", __base__=CommonParams, sede=(int, 0))
    with_typo = create_model("Params", __base__=Params, common=(sede, ...))
    assert set(undocumented(with_typo, page)) - set(undocumented(Params, page)) == {"common.sede"}
    assert "common.seed" not in documented_params(page.replace("| `common.seed` |", "| seed |"))


# --- table schemas ----------------------------------------------------------------------

SCHEMAS = [v for v in vars(skt_lib.schemas).values() if isinstance(v, TableSchema)]


@pytest.mark.parametrize("schema", SCHEMAS, ids=lambda s: s.name)
def test_every_schema_column_documented(schema):
    marker = f"(schema `{schema.name}` v{schema.version})"
    found = {p.relative_to(ROOT).as_posix(): section(p.read_text(), marker) for p in DOCS}
    found = {page: text for page, text in found.items() if text}
    assert len(found) == 1, f"{marker}: expected one docs section with it, found {sorted(found)}"
    (page, text), = found.items()
    missing = [c for c in schema.columns if f"`{c}`" not in text]
    assert not missing, f"{page} {marker}: columns not documented: {missing}"


NPZ_SPECS = {"data/render_views/<support_id>.npz": "skt_lib.perception.views:RENDER_SPEC",
             "data/affordance_maps/<support_id>.npz": "skt_lib.learning.data:AFF_SPEC"}


@pytest.mark.parametrize("heading", NPZ_SPECS)
def test_every_checked_npz_key_documented(heading):
    module, name = NPZ_SPECS[heading].split(":")
    spec = getattr(importlib.import_module(module), name)
    text = section((ROOT / "docs" / "pipeline.md").read_text(), f"`{heading}`")
    missing = [k for k in spec if f"`{k}`" not in text]
    assert text and not missing, f"docs/pipeline.md `{heading}`: keys not documented: {missing}"


def test_all_tables_have_a_schema():
    assert {s.name for s in SCHEMAS} >= {"supports", "objects", "contacts", "keypoints", "skts",
                                         "labels", "trials"}


# --- front page and run figures ---------------------------------------------------------

def test_readme_is_a_front_page():
    text = README.read_text()
    assert len(text) <= 10_000, f"README.md has {len(text)} characters, at most 10,000"
    assert "(reports/sim_eval/rerun.png)" in text
    assert (ROOT / "reports/sim_eval/rerun.png").is_file()


def test_run_figures_are_the_committed_reports():
    diffs = docs_results.stale(ROOT)
    assert not diffs, ("run figures differ from the reports; run `.venv/bin/python -m "
                       "tools.docs_results`:\n" + "\n".join(diffs))


def test_readme_table_one_has_every_method():
    metrics = json.loads((ROOT / docs_results.METRICS).read_text())
    block = docs_results.read_block(README.read_text(), "results")
    for method in docs_results.table_methods(metrics):
        assert f"| `{method}` |" in block or f"| `{method}` (best of " in block
    assert docs_results.table_methods(metrics), "no method with a success rate in metrics.json"


def test_every_bench_key_is_described():
    bench = json.loads((ROOT / docs_results.BENCH).read_text())
    unknown = set(bench) - set(docs_results.BENCH_ROWS) - set(docs_results.BENCH_SAMPLE)
    assert not unknown, f"bench.json keys without a row in tools/docs_results.py: {sorted(unknown)}"


def test_table_one_formats():
    metrics = {"n_test_supports": 2, "n_test_objects": 3,
               "zeta": {"success": {"all": 0.5, "easy": None, "normal": 1.0, "hard": 0.0,
                                    "very_hard": 0.125}},
               "sctdn": {"success": {"all": 0.1049, "easy": 0.2, "normal": 0.3, "hard": 0.4,
                                     "very_hard": 0.5}},
               "paired": {"sctdn_vs_zeta": {}}}
    table = docs_results.table_one(metrics)
    assert "on 2 test supports × 3 test objects" in table
    rows = [r for r in table.splitlines() if r.startswith("| `")]
    assert rows == ["| `sctdn` | 10.5 | 20.0 | 30.0 | 40.0 | 50.0 |",  # the paper's order first
                    "| `zeta` | 50.0 | – | 100.0 | 0.0 | 12.5 |"]
    # a proposing method: its best-of-N row, then its one-SKT row with its own interval
    metrics["skt_flow"] = {"success": metrics["zeta"]["success"], "n_proposals": 10,
                           "success_single": metrics["sctdn"]["success"],
                           "success_single_support_ci95": {"all": [0.05, 0.2]}}
    rows = [r for r in docs_results.table_one(metrics).splitlines() if r.startswith("| `")]
    assert rows[1:3] == ["| `skt_flow` (best of 10) | 50.0 | – | 100.0 | 0.0 | 12.5 |",
                         "| `skt_flow`, one SKT | 10.5 [5.0–20.0] | 20.0 | 30.0 | 40.0 | 50.0 |"]


def test_table_one_adds_the_seed_spread_or_says_why_not():
    rates = {"all": 0.5, "easy": None, "normal": 1.0, "hard": 0.0, "very_hard": 0.25}
    metrics = {"sctdn": {"success": rates},
               "seeds": {"status": "ok", "seeds": [7, 8, 9],
                         "sctdn": {"success_mean": rates,
                                   "success_min": {**rates, "all": 0.4},
                                   "success_max": {**rates, "all": 0.61}},
                         "paper_orderings": []}}
    table = docs_results.table_one(metrics)
    assert "training seeds 7, 8, 9" in table
    assert "| `sctdn` | 50.0 [40.0–61.0] | – | 100.0 [100.0–100.0] |" in table
    metrics["seeds"] = {"status": "stale", "reason": "made from other inputs"}
    assert "Over training seeds: not merged (made from other inputs)." in docs_results.table_one(
        metrics)


def test_check_fails_on_an_edited_figure_and_the_tool_repairs_it(tmp_path, capsys):
    for rel in ("README.md", "docs/presets.md", docs_results.METRICS, docs_results.BENCH,
                docs_results.SCALING, docs_results.PAPER_METRICS):
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(ROOT / rel, tmp_path / rel)
    readme = tmp_path / "README.md"
    block = docs_results.read_block(readme.read_text(), "results")
    row = next(r for r in block.splitlines() if r.startswith("| `"))
    edited = re.sub(r"\| (\d+)\.(\d) \|", lambda m: f"| {int(m.group(1)) + 1}.{m.group(2)} |",
                    row, count=1)
    assert edited != row
    readme.write_text(readme.read_text().replace(row, edited))
    assert docs_results.main(["--check", "--root", str(tmp_path)]) == 1
    out = capsys.readouterr().out
    assert f"-{edited}" in out and f"+{row}" in out
    assert docs_results.main(["--root", str(tmp_path)]) == 0
    assert docs_results.main(["--check", "--root", str(tmp_path)]) == 0
    assert readme.read_text() == README.read_text()


def test_missing_marker_or_report_is_one_error(tmp_path, capsys):
    (tmp_path / "README.md").write_text("no markers\n")
    assert docs_results.main(["--check", "--root", str(tmp_path)]) == 2
    assert capsys.readouterr().err.startswith("ERROR: reports/sim_eval/metrics.json: not found")
    with pytest.raises(docs_results.DocsError, match="README.md: needs exactly one"):
        docs_results.write_block("no markers\n", "results", "x", "README.md")


def test_paper_table_one_has_the_published_and_default_rows_beside_it():
    """The README's Table I from the paper run: each row's own levels and interval, the
    SKT-Hang paper's published All where it has the method, the default's All, and the
    training seeds' All once merged."""
    def entry(all_, single=None):
        e = {"success": {"all": all_, "easy": 0.9, "normal": 0.8, "hard": 0.7, "very_hard": 0.5},
             "success_support_ci95": {"all": [all_ - 0.1, all_ + 0.1]}}
        if single is not None:
            e.update(n_proposals=10, success_single={"all": single, "easy": 0.5, "normal": 0.5,
                                                     "hard": 0.5, "very_hard": 0.25})
        return e
    paper = {"n_test_supports": 60, "n_test_objects": 10, "sctdn": entry(0.6),
             "vatmart_mod": entry(0.8, 0.55), "skt_flow": entry(0.7, 0.65)}
    default = {"sctdn": entry(0.535), "vatmart_mod": entry(0.855, 0.62)}
    table = docs_results.paper_table_one(paper, default)
    assert "60 test supports × 10 test objects" in table and "| seeds |" not in table
    assert "| `sctdn` | 60.0 [50.0–70.0] | 90.0 | 80.0 | 70.0 | 50.0 | 83.7 | 53.5 |" in table
    assert "| `vatmart_mod` (best of 10) | 80.0 [70.0–90.0] | 90.0 | 80.0 | 70.0 | 50.0 | 72.1 | 85.5 |" in table
    assert "| `vatmart_mod`, one SKT | 55.0 | 50.0 | 50.0 | 50.0 | 25.0 | – | 62.0 |" in table
    assert "| `skt_flow` (best of 10) | 70.0 [60.0–80.0] | 90.0 | 80.0 | 70.0 | 50.0 | – | – |" in table
    paper["seeds"] = {"status": "ok", "seeds": [0, 1, 2], "sctdn": {
        "success_mean": {"all": 0.6}, "success_min": {"all": 0.55}, "success_max": {"all": 0.7}}}
    table = docs_results.paper_table_one(paper, default)
    assert "| SKT-Hang | default | seeds |" in table
    assert "| `sctdn` | 60.0 [50.0–70.0] | 90.0 | 80.0 | 70.0 | 50.0 | 83.7 | 53.5 | 60.0 [55.0–70.0] |" in table
    paper["seeds"] = {"status": "stale", "reason": "made from other inputs"}
    assert "seed step (two more seeds" in docs_results.paper_table_one(paper, default)
