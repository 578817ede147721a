"""docs/results.md and docs/performance.md are rendered from docs/data/*.toml and the result files under docs/.

A number a result file holds is read from it, so editing the file without re-rendering leaves a stale
page, which `eval/render_pages.py --check` (and this test) reports.
"""

from __future__ import annotations

import importlib.util
import json
import re
import shutil
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _module(name: str):
    spec = importlib.util.spec_from_file_location(name, ROOT / "eval" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


render_pages = _module("render_pages")


def test_the_committed_pages_are_what_the_renderer_writes(capsys):
    assert render_pages.main(["--check"]) == 0, capsys.readouterr().err


@pytest.fixture
def repo(tmp_path: Path) -> Path:
    """A copy of docs/ (pages, data files, result files) and README.md to change without touching the checkout."""
    shutil.copytree(ROOT / "docs", tmp_path / "docs")
    shutil.copy(ROOT / "README.md", tmp_path / "README.md")
    return tmp_path


def _edit_json(path: Path, change) -> None:
    data = json.loads(path.read_text())
    change(data)
    path.write_text(json.dumps(data, indent=2) + "\n")


def test_a_changed_number_makes_its_page_stale(repo, capsys):
    _edit_json(repo / "docs" / "bench_fbx.json", lambda d: d.update(fbx_adds_ms=42.0))
    assert render_pages.main(["--check", "--root", str(repo)]) == 1
    err = capsys.readouterr().err
    assert "docs/performance.md" in err and "docs/results.md" not in err and "eval/render_pages.py" in err
    assert err.count("\n") == 1  # one line
    assert render_pages.main(["--root", str(repo)]) == 0
    assert "**42.0 ms** per garage" in (repo / "docs" / "performance.md").read_text()
    assert render_pages.main(["--check", "--root", str(repo)]) == 0


def test_a_result_files_own_provenance_is_what_the_page_says(repo):
    prov = {"command": ".venv/bin/python eval/bench_fbx.py --json docs/bench_fbx.json --repeat 9",
            "date": "2031-01-02", "machine": "a 64-core test machine", "commit": "abcdef1"}
    _edit_json(repo / "docs" / "bench_fbx.json", lambda d: d.update(provenance=prov))
    assert render_pages.main(["--root", str(repo)]) == 0
    page = (repo / "docs" / "performance.md").read_text()
    details = page[page.index("### FBX export"):]
    details = details[:details.index("\n#")]
    assert all(v in details for v in prov.values()), details


def test_a_new_protocol_summary_adds_its_section(repo):
    """A full-scale summary.json (extra keys allowed) and one [[section]] in results.toml add its table."""
    summary = json.loads((ROOT / "docs" / "protocol_10pct" / "summary.json").read_text())
    summary["m5_13x13_aligned"]["garages"] = 123456
    summary.update(timesteps_per_run=2_000_000, runs=[{"map": "tiny_7x11", "seed": 0}])
    (repo / "docs" / "protocol_new").mkdir()
    (repo / "docs" / "protocol_new" / "summary.json").write_text(json.dumps(summary))
    with (repo / "docs" / "data" / "results.toml").open("a") as f:
        f.write('\n[[section]]\nheading = "The full protocol"\nprotocol = "protocol_new"\n'
                'name = "Full protocol"\nheadline = "{{protocol_new/summary.json:*.garages|sum|,}} garages"\n'
                'body = "{{protocol_new/summary.json:timesteps_per_run|,}} timesteps per run."\n'
                '[[section.figure]]\nfiles = ["protocol_new/summary.json"]\n'
                'command = "eval/protocol_summary.py runs/paper"\ndate = "2031-01-02"\ncommit = "abcdef1"\n'
                'machine = "dev"\n')
    assert render_pages.main(["--root", str(repo)]) == 0
    page = (repo / "docs" / "results.md").read_text()
    section = page[page.index("## The full protocol"):]
    assert "2,000,000 timesteps per run." in section
    assert re.search(r"^\| m5_13x13_aligned \| 123,456 \| 0\.33-0\.91 \(7\) \| 33% / 60% \| 255\.3 \(19\.8\) \|$",
                     section, re.M), section
    assert len(re.findall(r"^\| (tiny|m\d)_", section, re.M)) == 5  # "runs" and the run length are no map
    assert re.search(r"^\| \[Full protocol\]\(#the-full-protocol\) \| [\d,]+ garages \| - \| - \|$", page, re.M)


def test_each_page_leads_with_a_short_table_that_links_to_its_details():
    for name in ("performance", "results"):
        page = (ROOT / "docs" / f"{name}.md").read_text()
        body = page[page.index("\n# "):]
        first_table = body[body.index("\n|") + 1:].split("\n\n")[0]
        assert first_table.splitlines()[1] == "|---|---|---|---|", first_table
        assert body.index("\n|") < body.index("\n## ")  # before the first section
        anchors = set(re.findall(r"^#+ (.+)$", page, re.M))
        for row in first_table.splitlines()[2:]:
            what, figure, target, met = (c.strip() for c in row.strip("|").split(" | "))
            anchor = re.fullmatch(r"\[.+\]\(#(.+)\)", what).group(1)
            assert anchor in {render_pages.slug(a) for a in anchors}, row
            assert met in ("yes", "no", "partly", "-") and len(figure.split()) <= 40, row


def test_met_is_computed_from_the_comparisons_it_names(repo):
    path = repo / "docs" / "data" / "performance.toml"
    text = path.read_text()
    met = 'met = "{{bench_fbx.json:fbx_adds_ms}} <= {{bench_fbx.json:target_ms}}"'
    assert met in text
    row = next(line for line in (repo / "docs" / "performance.md").read_text().splitlines()
               if line.startswith("| [FBX export]"))
    assert row.endswith(" | yes |")
    _edit_json(repo / "docs" / "bench_fbx.json", lambda d: d.update(fbx_adds_ms=999.0))
    path.write_text(text.replace(met, met[:-1] + ' and 1 < 2"'))
    assert render_pages.main(["--root", str(repo)]) == 0
    row = next(line for line in (repo / "docs" / "performance.md").read_text().splitlines()
               if line.startswith("| [FBX export]"))
    assert "**999.0 ms**" in row and row.endswith(" | partly |")


def test_a_met_that_is_no_verdict_is_one_line(repo, capsys):
    path = repo / "docs" / "data" / "performance.toml"
    path.write_text(path.read_text().replace('met = "{{bench_fbx.json:fbx_adds_ms}} <=', 'met = "mostly {{bench_fbx.json:fbx_adds_ms}} <='))
    assert "none of yes, no, partly, -" in _one_error_line(repo, capsys)


def test_the_readme_results_table_reads_its_numbers_from_the_result_files(repo, capsys):
    readme = (ROOT / "README.md").read_text()
    block = readme[readme.index("<!-- results:begin"):readme.index("<!-- results:end -->")]
    summary = json.loads((ROOT / "docs" / "paper_validation_summary.json").read_text())
    assert f"**{summary['r']:.3f}**" in block
    assert block.index("protocol_100pct") < block.index("paper_validation_summary.json")  # full scale first
    _edit_json(repo / "docs" / "paper_validation_summary.json", lambda d: d.update(r=-0.123))
    assert render_pages.main(["--check", "--root", str(repo)]) == 1
    assert "README.md" in capsys.readouterr().err
    assert render_pages.main(["--root", str(repo)]) == 0
    text = (repo / "README.md").read_text()
    assert "**-0.123**" in text and text[:text.index("<!-- results:begin")] == readme[:readme.index("<!-- results:begin")]
    assert text[text.index("<!-- results:end -->"):] == readme[readme.index("<!-- results:end -->"):]


def test_a_readme_without_its_markers_is_one_line(repo, capsys):
    path = repo / "README.md"
    path.write_text(path.read_text().replace("<!-- results:end -->", ""))
    assert "README.md has no <!-- results:begin" in _one_error_line(repo, capsys)


def test_a_placeholder_naming_a_missing_key_says_which(repo, capsys):
    path = repo / "docs" / "data" / "performance.toml"
    path.write_text(path.read_text().replace("{{bench_fbx.json:fbx_adds_ms|.1f}}", "{{bench_fbx.json:fbx_ms|.1f}}"))
    assert render_pages.main(["--check", "--root", str(repo)]) == 1
    assert "{{bench_fbx.json:fbx_ms|.1f}}: no 'fbx_ms'" in capsys.readouterr().err


def test_the_pages_say_they_are_generated():
    for page in ("results", "performance"):
        first = (ROOT / "docs" / f"{page}.md").read_text().splitlines()[0]
        assert first.startswith("<!-- Generated by") and "eval/render_pages.py" in first


def test_every_eval_script_is_indexed_in_its_readme():
    readme = (ROOT / "eval" / "README.md").read_text()
    missing = [p.name for p in sorted((ROOT / "eval").glob("*.py"))
               if not p.name.startswith("_") and f"`{p.name}`" not in readme]
    assert not missing, f"eval/README.md does not index {missing}"


def test_provenance_names_the_command_date_machine_and_commit():
    p = _module("_provenance").provenance(["--json", "out.json"], script=str(ROOT / "eval" / "bench_fbx.py"))
    assert p["command"] == ".venv/bin/python eval/bench_fbx.py --json out.json"
    assert re.fullmatch(r"\d{4}-\d\d-\d\d", p["date"]) and p["machine"] and p["commit"]


def _one_error_line(repo: Path, capsys) -> str:
    """render_pages' error for REPO: exit status 1, one line, no page written."""
    before = {p: p.read_text() for p in (repo / "docs" / "performance.md", repo / "docs" / "results.md")}
    assert render_pages.main(["--root", str(repo)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("render_pages: "), err
    assert {p: p.read_text() for p in before} == before  # nothing written
    return err


def test_a_truncated_result_file_is_one_line_naming_it(repo, capsys):
    path = repo / "docs" / "bench_fbx.json"
    path.write_text(path.read_text()[:40])
    err = _one_error_line(repo, capsys)
    assert "docs/bench_fbx.json is not valid JSON" in err and "run its benchmark again" in err


def test_a_nan_in_a_result_file_is_refused_naming_the_file_and_key(repo, capsys):
    _edit_json(repo / "docs" / "bench_fbx.json", lambda d: d.update(fbx_adds_ms=float("nan")))
    err = _one_error_line(repo, capsys)
    assert "docs/bench_fbx.json" in err and "fbx_adds_ms" in err and "NaN" in err and "nan**" not in err


def test_a_nan_in_a_csv_result_file_is_refused_naming_the_row(repo, capsys):
    import csv

    path = repo / "docs" / "compare_learners.csv"
    with path.open(newline="") as f:
        rows = list(csv.reader(f))
    rows[1][rows[0].index("garages_mean")] = "inf"
    with path.open("w", newline="") as f:
        csv.writer(f).writerows(rows)
    err = _one_error_line(repo, capsys)
    assert "docs/compare_learners.csv" in err and "row 1" in err and "garages_mean" in err and "inf" in err


@pytest.mark.parametrize("name", ["../outside.json", "../../../../../../{tmp}/outside.json", "/{tmp}/outside.json",
                                  "/etc/passwd", "link.json"])
def test_a_placeholder_reads_only_files_under_docs(repo, capsys, name):
    (repo / "outside.json").write_text('{"x": 123456789}')
    (repo / "docs" / "link.json").symlink_to(repo / "outside.json")
    name = name.format(tmp=str(repo).lstrip("/"))
    path = repo / "docs" / "data" / "performance.toml"
    path.write_text(path.read_text().replace("{{bench_fbx.json:fbx_adds_ms|.1f}}", f"{{{{{name}:x}}}}"))
    err = _one_error_line(repo, capsys)
    assert "outside docs/" in err and "123456789" not in err


def test_a_bad_placeholder_operation_is_one_line(repo, capsys):
    path = repo / "docs" / "data" / "performance.toml"
    text = path.read_text()
    for bad, said in (("{{bench_fbx.json:fbx_adds_ms|x.|.1f}}", "x."),
                      ("{{bench_fbx.json:fbx_adds_ms|x1e999|.1f}}", "x1e999"),
                      ("{{bench_drivable.json:rows.driver=nobody.tests|sum}}", "no 'tests'"),
                      ("{{bench_drivable.json:rows.driver=nobody|max}}", "max"),
                      ("{{bench_drivable.json:rows.driver|max}}", "driver")):
        path.write_text(text.replace("{{bench_fbx.json:fbx_adds_ms|.1f}}", bad))
        assert said in _one_error_line(repo, capsys)


def test_the_plots_are_drawn_from_the_result_files_the_same_each_time(tmp_path):
    """eval/plot_pages.py draws every plot a page embeds, the same bytes from the same files (a committed PNG
    matches byte for byte only under the matplotlib that drew it, so that is not asserted here)."""
    plot_pages = _module("plot_pages")
    embedded = set(re.findall(r"\]\((plots/[^)]+\.png)\)", (ROOT / "docs" / "results.md").read_text()
                              + (ROOT / "docs" / "performance.md").read_text()))
    assert embedded == {f"{plot_pages.OUT}/{name}" for name in plot_pages.PLOTS}
    shutil.copytree(ROOT / "docs", tmp_path / "docs")
    assert plot_pages.main(["--root", str(tmp_path)]) == 0
    first = {p.name: p.read_bytes() for p in (tmp_path / "docs" / "plots").glob("*.png")}
    assert set(first) == set(plot_pages.PLOTS)
    assert plot_pages.main(["--check", "--root", str(tmp_path)]) == 0
    assert all(png.startswith(b"\x89PNG") and b"matplotlib" not in png for png in first.values())
