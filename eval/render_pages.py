"""Render docs/performance.md, docs/results.md and README.md's results table from docs/data/*.toml and the
result files they name.

Every figure on the two pages is a record in its page's data file: what it measures, the figure's
text, the command that made it, the result files under docs/ it comes from (``files``), the date,
the machine and the commit. A number a result file holds is not copied into the text: a placeholder
reads it from the file at render time, so a page cannot drift from its files.

Each page leads with a short table, one row per record (a performance row, a results section): its
``name`` (linking to the record's details, its heading), ``headline`` (the figure in a few words),
``goal`` (the target or the paper's claim) and ``met`` (yes, no, partly or -, or comparisons of two
numbers joined by " and ", e.g. ``{{bench_fbx.json:fbx_adds_ms}} <= {{bench_fbx.json:target_ms}}``,
which render as yes when all hold, no when none, partly otherwise). A record's ``plot`` (a PNG under
docs/, drawn by eval/plot_pages.py from result files) is embedded at the top of its details. README.md's
table between ``<!-- results:begin`` and ``<!-- results:end -->`` is rendered from docs/data/readme.toml;
the rest of the README is left as it is.

    {{FILE:PATH|OP|SPEC}}   e.g. {{bench_fbx.json:fbx_adds_ms|.1f}}, {{bench_park.json:per_kind.*.oracle.sim_s_per_wall_s|range|.0f}}

    FILE  a .json or .csv file under docs/ (a CSV is a list of rows); a name leading outside docs/ (``..``, an
          absolute path, a symlink) is refused, and so is a file holding a NaN or infinite number
    PATH  dot-separated keys (a list index is a number); ``*`` takes every value, ``k=v,k2=v2`` every
          item whose keys have those values: both give a list (of the values that have the keys
          after it), which an OP must reduce
    OP    on a list: sum, min, max, mean, len, first, range (min and max, written "lo-hi"), list
          (written "a, b, c"); xNUMBER multiplies (x0.001: bytes to kB)
    SPEC  a Python format spec for the value (``.1f``, ``,``, ``.0%``, ``+.0f``); last, optional

A result file's own ``provenance`` (written by the benchmarks through eval/_provenance.py) is used
over the record's command, date, machine and commit. Records whose files do not carry one get their
date and commit from git once, with ``--stamp`` (the commit that last changed the files' content),
so that rendering needs neither git nor a full clone.

    .venv/bin/python eval/render_pages.py           # write docs/performance.md, docs/results.md, README.md's table
    .venv/bin/python eval/render_pages.py --check   # exit 1 if a committed page (or the README's table) is stale
    .venv/bin/python eval/render_pages.py --stamp   # then render: date and commit from git where files changed

A new figure: its result file under docs/ (the benchmark's ``--json``), one record in
docs/data/performance.toml or docs/data/results.toml, then ``--stamp`` (after committing the result
file, unless it carries its provenance) and a render; commit the data file and the page.
"""

from __future__ import annotations

import argparse
import csv
import fnmatch
import json
import math
import re
import statistics
import subprocess
import sys
import unicodedata
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

try:
    import tomllib
except ModuleNotFoundError:  # Python < 3.11
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]
RENDER = ".venv/bin/python eval/render_pages.py"
PROVENANCE_FIELDS = ("command", "date", "machine", "commit")
PLACEHOLDER = re.compile(r"\{\{(?P<file>[^:{}]+):(?P<path>[^|{}]*)(?P<ops>(?:\|[^|{}]*)*)\}\}")


class PageError(Exception):
    """A data file or result file that cannot render: one sentence naming it and the fix."""


# --- result files -------------------------------------------------------------------------------

def _number(text: str) -> Any:
    """A CSV cell as int, float or the text itself."""
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def _csv_rows(path: Path, name: str) -> list[dict]:
    """A CSV result file's rows (cells as numbers where they read as one); a row whose cells do not match the
    header is a :class:`PageError`."""
    with path.open(newline="") as f:
        reader = csv.DictReader(f)
        rows = []
        for i, row in enumerate(reader, 1):
            if None in row or None in row.values():
                raise PageError(f"docs/{name} row {i} has {'more' if None in row else 'fewer'} cells than its "
                                "header: run its benchmark again")
            rows.append({k: _number(v) for k, v in row.items()})
    return rows


def _not_finite(node: Any, path: tuple = ()) -> tuple[tuple, float] | None:
    """The key path and value of the first NaN or infinite number in a result file's data, if any."""
    if isinstance(node, float) and not math.isfinite(node):
        return path, node
    for key, value in (node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()):
        found = _not_finite(value, (*path, key))
        if found:
            return found
    return None


def _where_in(name: str, path: tuple) -> str:
    """A key path of docs/NAME as its error names it: "key a.b.c", or a CSV's "row N, column C"."""
    if name.endswith(".csv") and len(path) == 2:
        return f"row {path[0] + 1}, column {path[1]}"
    return f"key {'.'.join(str(k) for k in path)}"


def _drivable_totals(rows: list[dict]) -> dict:
    """bench_drivable.json's groups summed per "driver/action_type" (tests, infeasible, feasible, success)."""
    totals: dict[str, dict] = {}
    for r in rows:
        t = totals.setdefault(f"{r['driver']}/{r['action_type']}",
                              {"tests": 0, "infeasible": 0, "feasible": 0, "success": 0})
        t["tests"] += r["tests"]
        t["infeasible"] += r["infeasible"]
        t["feasible"] += r["feasible"]
        t["success"] += round(r["success_pct"] * r["feasible"] / 100)
    for t in totals.values():
        t["infeasible_pct"] = 100 * t["infeasible"] / t["tests"]
        t["success_pct"] = 100 * t["success"] / t["feasible"]
        t["failed"] = t["feasible"] - t["success"]
    return {"rows": rows, "totals": totals}


def _protocol_widths(summary: dict) -> dict:
    """A protocol summary.json with each map's difficulty range width (diff_width = max - min)."""
    return {m: {**v, "diff_width": v["diff"][1] - v["diff"][0]} if isinstance(v, dict) and "diff" in v else v
            for m, v in summary.items()}


def _actors_replay(data: dict) -> dict:
    """bench_actors.json with the replay's wall seconds per replayed test."""
    replay = data.get("replay", {})
    if replay.get("replayed"):
        replay = {**replay, "s_per_test": replay["wall_s"] / replay["replayed"]}
    return {**data, "replay": replay}


def _drive_env_meta(data: dict) -> dict:
    """bench_drive_env.json records its date and measured commit in "meta" (written before "provenance")."""
    meta = data.get("meta", {})
    return {"date": meta.get("when", "")[:10], "commit": meta.get("trees", {}).get("after", {}).get("commit", "")}


@dataclass(frozen=True)
class View:
    """What a result file gives the pages beyond its own keys: derived figures, an older provenance record."""

    file: str  # path under docs/, a glob pattern (fnmatch)
    derive: Callable[[Any], Any] | None = None  # the data the placeholders read, from the file's
    provenance: Callable[[Any], dict] | None = None  # fields for a file written before "provenance"


VIEWS = (
    View("bench_drivable.json", derive=_drivable_totals),
    View("bench_actors.json", derive=_actors_replay),
    View("bench_drive_env.json", provenance=_drive_env_meta),
    View("protocol_*/summary.json", derive=_protocol_widths),
)


def _view(name: str) -> View | None:
    """The view of docs/NAME, if one is registered."""
    return next((v for v in VIEWS if fnmatch.fnmatch(name, v.file)), None)


class Sources:
    """The result files under a docs/ folder, each read once."""

    def __init__(self, docs: Path) -> None:
        self.docs = docs
        self._raw: dict[str, Any] = {}

    def raw(self, name: str) -> Any:
        """The file's content as written (JSON, or a CSV's rows)."""
        if name not in self._raw:
            path = self._path(name)
            try:
                if path.suffix == ".csv":
                    raw = _csv_rows(path, name)
                else:
                    raw = json.loads(path.read_text())
            except (ValueError, RecursionError) as exc:  # JSONDecodeError, UnicodeDecodeError (a binary file)
                what = "valid JSON" if path.suffix == ".json" else "a valid CSV file"
                raise PageError(f"docs/{name} is not {what} ({str(exc)[:120]}): run its benchmark again, "
                                f"or restore it (git checkout -- docs/{name})") from None
            except (OSError, csv.Error) as exc:
                raise PageError(f"docs/{name} cannot be read ({exc}): check the file and its permissions") from None
            bad = _not_finite(raw)
            if bad:
                key, value = bad
                said = "NaN" if math.isnan(value) else str(value)
                raise PageError(f"docs/{name}: {_where_in(name, key)} is {said}, not a figure a page can show: "
                                "run its benchmark again (or write null where it measured nothing)")
            self._raw[name] = raw
        return self._raw[name]

    def _path(self, name: str) -> Path:
        """docs/NAME, which must be a .json or .csv file inside docs/ (symlinks resolved)."""
        docs = self.docs.resolve()
        path = (self.docs / name).resolve()
        if not path.is_relative_to(docs):
            raise PageError(f"{name!r} is outside docs/: placeholders and a record's files read result files "
                            "under docs/ only (e.g. bench_fbx.json); move the file there and name it so")
        if path.suffix not in (".json", ".csv"):
            raise PageError(f"docs/{name} is not a .json or .csv file: name the result file a benchmark wrote")
        if not path.is_file():
            raise PageError(f"docs/{name} does not exist: fix the name in the data file or run its benchmark")
        return path

    def data(self, name: str) -> Any:
        """What the placeholders read: the file, through its view's derive if it has one."""
        view = _view(name)
        return view.derive(self.raw(name)) if view and view.derive else self.raw(name)

    def provenance(self, name: str) -> dict:
        """The file's own provenance fields ("provenance", or its view's reading of an older record)."""
        raw = self.raw(name)
        if isinstance(raw, dict) and isinstance(raw.get("provenance"), dict):
            return raw["provenance"]
        view = _view(name)
        return {k: v for k, v in view.provenance(raw).items() if v} if view and view.provenance else {}

    def fill(self, text: str) -> str:
        """TEXT with every placeholder replaced by the figure it names."""
        return PLACEHOLDER.sub(lambda m: self._figure(m), text)

    def _figure(self, m: re.Match) -> str:
        where = m.group(0)
        ops = m.group("ops").split("|")[1:]
        spec = ops.pop() if ops and not _is_op(ops[-1]) else ""
        value, many = _walk(self.data(m.group("file").strip()), m.group("path").strip(), where)
        for op in ops:
            if not _is_op(op):
                raise PageError(f"{where}: unknown operation {op!r} (one of {', '.join(REDUCE)}, xNUMBER)")
            try:
                if op.startswith("x"):
                    factor = _factor(op, where)
                    value = [v * factor for v in value] if many else value * factor
                    continue
                if not many:
                    raise PageError(f"{where}: {op} needs a list (a * or k=v step in the path)")
                value, many = REDUCE[op](value), False
            except PageError:
                raise
            except (TypeError, ValueError, IndexError) as exc:  # a reduction of no values, or of text
                raise PageError(f"{where}: cannot take {op} of {str(value)[:80]} ({exc}): check the path") from None
        if many:
            raise PageError(f"{where} names {len(value)} values: reduce them with |sum, |range, |list ...")
        return _format(value, spec, where)


def _items(node: Any) -> list[tuple[str, Any]]:
    """A dict's or list's (key, value) pairs; a result's "provenance" is no figure."""
    if isinstance(node, dict):
        return [(k, v) for k, v in node.items() if k != "provenance"]
    if isinstance(node, list):
        return [(str(i), v) for i, v in enumerate(node)]
    return []


def _walk(data: Any, path: str, where: str) -> tuple[Any, bool]:
    """The value (or, after a * or k=v step, the list of values) at PATH, and whether it is a list."""
    values, many = [data], False
    for step in path.split(".") if path else []:
        if step == "*":
            values, many = [v for node in values for _, v in _items(node)], True
        elif "=" in step:
            if not all("=" in part for part in step.split(",")):
                raise PageError(f"{where}: {step!r} mixes k=v and plain keys; write k=v,k2=v2")
            want = dict(part.split("=", 1) for part in step.split(","))
            values = [v for node in values for _, v in _items(node)
                      if isinstance(v, dict) and all(str(v.get(k)) == x for k, x in want.items())]
            many = True
        else:
            found = [v for node in values for k, v in _items(node) if k == step]
            if not found or (not many and len(found) != len(values)):  # after a * a value may lack it
                keys = f"its keys: {', '.join(k for k, _ in _items(values[0]))[:200]}" if values else "no values"
                raise PageError(f"{where}: no {step!r} in the file ({keys})")
            values = found
    return (values if many else values[0]), many


REDUCE: dict[str, Callable[[list], Any]] = {
    "sum": sum, "min": min, "max": max, "mean": statistics.fmean, "len": len,
    "first": lambda v: v[0], "range": lambda v: (min(v), max(v)), "list": list,
}


def _is_op(text: str) -> bool:
    """Whether a |part of a placeholder is an operation (a reduction, or xNUMBER: times NUMBER), not a spec."""
    return text in REDUCE or re.fullmatch(r"x[0-9.eE+-]+", text) is not None


def _factor(op: str, where: str) -> float:
    """The finite number of an xNUMBER operation."""
    try:
        factor = float(op[1:])
    except ValueError:
        factor = math.nan
    if not math.isfinite(factor):
        raise PageError(f"{where}: {op!r} does not multiply by a finite number (write e.g. x0.001)")
    return factor


def _format(value: Any, spec: str, where: str) -> str:
    """A figure as the page writes it; a range as "lo-hi" (one number where both ends read the same)."""
    if isinstance(value, tuple):
        lo, hi = (_format(v, spec, where) for v in value)
        return lo if lo == hi else f"{lo}-{hi}"
    if isinstance(value, list):
        return ", ".join(_format(v, spec, where) for v in value)
    if value is None:
        raise PageError(f"{where} is null in the file: name a key that holds a figure")
    if isinstance(value, float) and not math.isfinite(value):
        raise PageError(f"{where} is {value}: check the path and its xNUMBER")
    try:
        return format(value, spec)
    except (TypeError, ValueError) as exc:
        raise PageError(f"{where}: cannot write {value!r} as {spec!r} ({exc})") from None


# --- records and pages --------------------------------------------------------------------------

MET = ("yes", "no", "partly", "-")
COMPARE = re.compile(r"^\s*(?P<a>[-+]?[\d,]*\.?\d+(?:[eE][-+]?\d+)?)\s*(?P<op><=|>=|<|>|==)\s*"
                     r"(?P<b>[-+]?[\d,]*\.?\d+(?:[eE][-+]?\d+)?)\s*$")
OPS: dict[str, Callable[[float, float], bool]] = {
    "<=": lambda a, b: a <= b, ">=": lambda a, b: a >= b, "<": lambda a, b: a < b, ">": lambda a, b: a > b,
    "==": lambda a, b: a == b,
}


def _one_line(text: str) -> str:
    """A table cell: the data file's line breaks as spaces."""
    return " ".join(text.split())


def slug(heading: str) -> str:
    """A heading's anchor as MkDocs' toc (and GitHub, for plain words) writes it."""
    text = unicodedata.normalize("NFKD", re.sub(r"<[^>]+>|`", "", heading)).encode("ascii", "ignore").decode()
    return re.sub(r"[-\s]+", "-", re.sub(r"[^\w\s-]", "", text).strip().lower())


def _met(record: dict, sources: Sources, label: str) -> str:
    """Whether a figure meets its target: yes, no, partly or - as written, or computed from comparisons of two
    numbers ("A <= B and C >= D", placeholders allowed): yes if all hold, no if none, partly otherwise."""
    text = _one_line(sources.fill(str(record.get("met", "-"))))
    if text in MET:
        return text
    held = []
    for part in text.split(" and "):
        m = COMPARE.match(part)
        if not m:
            raise PageError(f"{label}: met = {record.get('met')!r} is none of {', '.join(MET)} and no comparison "
                            "\"A <= B\" of two numbers (placeholders allowed; several joined by \" and \"): "
                            "write one of them")
        a, b = (float(m.group(k).replace(",", "")) for k in ("a", "b"))
        held.append(OPS[m.group("op")](a, b))
    return "yes" if all(held) else "no" if not any(held) else "partly"


def _summary(entries: list[tuple[str, str, dict]], sources: Sources) -> list[str]:
    """The table a page leads with: (label, anchor, record with name, headline, goal, met) per row."""
    lines = ["| what | figure | target | met? |", "|---|---|---|---|"]
    for label, anchor, record in entries:
        missing = [k for k in ("name", "headline") if not record.get(k)]
        if missing:
            raise PageError(f"{label} has no {' or '.join(missing)}: write the short fields the page's table shows")
        cells = [f"[{_one_line(record['name'])}](#{anchor})", sources.fill(record["headline"]),
                 sources.fill(record.get("goal", "")) or "-", _met(record, sources, label)]
        lines.append("| " + " | ".join(_one_line(c) for c in cells) + " |")
    return lines


def _plot(record: dict, sources: Sources, label: str) -> list[str]:
    """A record's picture (``plot``, a PNG under docs/ written by eval/plot_pages.py), as the page embeds it."""
    if not record.get("plot"):
        return []
    name = record["plot"]
    if not (sources.docs / name).is_file():
        raise PageError(f"{label}: plot docs/{name} does not exist: run `.venv/bin/python eval/plot_pages.py`")
    return [f"![{_one_line(record.get('plot_alt', name))}]({name})", ""]


def _unique_anchors(entries: list[tuple[str, str, dict]], taken: set[str]) -> None:
    """Every row's details heading must have an anchor of its own (or its link would land on another)."""
    for label, anchor, _ in entries:
        if anchor in taken:
            raise PageError(f"{label}: its heading's anchor #{anchor} is taken by another heading: rename it")
        taken.add(anchor)


def _provenance(record: dict, sources: Sources, label: str) -> dict[str, str]:
    """The record's command, date, machine and commit, each taken from its first file that records it."""
    out = {k: str(record.get(k, "")) for k in PROVENANCE_FIELDS}
    for name in reversed(record.get("files", [])):
        out.update({k: str(v) for k, v in sources.provenance(name).items() if k in PROVENANCE_FIELDS and v})
    missing = [k for k in PROVENANCE_FIELDS if not out[k]]
    if missing:
        fix = f"run `{RENDER} --stamp`" if record.get("files") else "write them into the data file"
        raise PageError(f"{label} has no {' or '.join(missing)}: {fix}")
    return out


def _machine(name: str, machines: dict[str, str]) -> str:
    """A machine's short name as the page writes it (a described machine in italics, the legend explains it)."""
    return f"*{name}*" if name in machines else name


def _legend(machines: dict[str, str], used: set[str]) -> list[str]:
    """The machines the page names, one line each."""
    return [f"- *{k}*: {v}" for k, v in machines.items() if k in used]


def _files_text(record: dict) -> str:
    """The record's result files as the page writes them."""
    return ", ".join(f"`docs/{f}`" for f in record.get("files", [])) or "printed by the command"


def _header(name: str) -> list[str]:
    """The comment that opens a rendered page."""
    return [f"<!-- Generated by `{RENDER}` from docs/data/{name}.toml and the result files it names: "
            f"edit those, not this page, then run the command. -->"]


def render_performance(data: dict, sources: Sources) -> str:
    """docs/performance.md: a short table (what, figure, target, met?), then each row's details and the
    command, files, date, commit and machine it comes from, then the prose sections."""
    machines, used = data.get("machines", {}), set()
    entries = [(f"docs/data/performance.toml row {i + 1} ({_one_line(row.get('name') or row['what'])[:40]})",
                slug(row.get("name", "")), row) for i, row in enumerate(data["row"])]
    _unique_anchors(entries, {slug(data["title"]), "details", "machines"}
                    | {slug(s["heading"]) for s in data.get("section", [])})
    details = ["## Details", ""]
    for label, _, row in entries:
        p = _provenance(row, sources, label)
        used.add(p["machine"])
        note = f" {_one_line(row['command_note'])}" if row.get("command_note") else ""
        details += [f"### {_one_line(row['name'])}", "", *_plot(row, sources, label),
                    f"- **measures**: {_one_line(sources.fill(row['what']))}",
                    f"- **figure**: {_one_line(sources.fill(row['figure']))}"]
        if row.get("target"):
            details.append(f"- **target**: {_one_line(sources.fill(row['target']))}")
        details += [f"- **command**: `{p['command']}`{note}",
                    f"- **result**: {_files_text(row)}; {p['date']}, `{p['commit']}`, {_machine(p['machine'], machines)}",
                    ""]
    lines = [*_header("performance"), f"# {data['title']}", "", sources.fill(data["intro"]).strip(), "",
             *_summary(entries, sources), "", *details[:-1]]
    for section in data.get("section", []):
        lines += ["", f"## {section['heading']}", "", *_plot(section, sources, section["heading"]),
                  sources.fill(section["body"]).strip()]
    lines += ["", "## Machines", "", *_legend(machines, used)]
    return "\n".join(lines) + "\n"


def _protocol_table(section: dict, map_order: list[str], sources: Sources) -> list[str]:
    """A protocol run's per-map table from docs/PROTOCOL/summary.json (maps: its entries with "garages")."""
    name = f"{section['protocol']}/summary.json"
    summary = sources.data(name)
    maps = [m for m, v in summary.items() if isinstance(v, dict) and "garages" in v]
    maps.sort(key=lambda m: (map_order.index(m) if m in map_order else len(map_order), m))
    notes = section.get("notes", {})
    lines = []
    if (sources.docs / section["protocol"] / "convergence.png").is_file():
        alt = section.get("figure_alt", f"convergence of the {section['protocol']} run, mean over seeds")
        lines += [f"![{alt}]({section['protocol']}/convergence.png)", ""]
    lines += ["| map | garages stored | difficulty range (0.1 bins) | coverage 0.6-0.8 / >= 0.8 "
              "| return, last 100 episodes (mean, sd over seeds) |", "|---|---|---|---|---|"]
    for m in maps:
        s = summary[m]
        note = f": {_one_line(notes[m])}" if m in notes else ""
        lines.append(f"| {m} | {s['garages']:,} | {s['diff'][0]:.2f}-{s['diff'][1]:.2f} ({s['bins']}) "
                     f"| {s['cov_share_06_08']:.0%} / {s['cov_share_ge_08']:.0%} "
                     f"| {s['ret_last100']:.1f} ({s['ret_sd']:.1f}){note} |")
    return lines


def _figure_line(record: dict, sources: Sources, machines: dict[str, str], label: str) -> str:
    """One line of a results section: which files hold its figures, the command, date, commit, machine."""
    p = _provenance(record, sources, label)
    what = f"{sources.fill(record['what'])}: " if record.get("what") else ""
    note = f" {_one_line(record['command_note'])}" if record.get("command_note") else ""
    return (f"- {what}{_files_text(record)}, made by `{p['command']}`{note}, on {p['date']} at commit "
            f"`{p['commit']}`, {_machine(p['machine'], machines)}")


def render_results(data: dict, sources: Sources) -> str:
    """docs/results.md: a short table (one row per section: what, figure, the paper's or our target, met?), then
    the sections (prose, protocol tables from their summary.json), each with its figures' origin."""
    machines, used = data.get("machines", {}), set()
    entries = [(f"docs/data/results.toml section {s['heading']!r}", slug(s["heading"]), s) for s in data["section"]]
    _unique_anchors(entries, {slug(data["title"]), "machines"})
    lines = [*_header("results"), f"# {data['title']}", "", sources.fill(data["intro"]).strip(), "",
             *_summary(entries, sources)]
    for label, _, section in entries:
        lines += ["", f"## {section['heading']}", "", *_plot(section, sources, label)]
        if section.get("body"):
            lines += [sources.fill(section["body"]).strip(), ""]
        if section.get("protocol"):
            lines += [*_protocol_table(section, data.get("map_order", []), sources), ""]
        if section.get("after"):
            lines += [sources.fill(section["after"]).strip(), ""]
        figures = section.get("figure", [])
        if figures:
            lines += ["Where the figures come from:", ""]
        for j, record in enumerate(figures):
            figure_label = f"{label}, figure {j + 1}"
            lines.append(_figure_line(record, sources, machines, figure_label))
            used.add(_provenance(record, sources, figure_label)["machine"])
        while lines[-1] == "":
            lines.pop()
    lines += ["", "## Machines", "", *_legend(machines, used)]
    return "\n".join(lines) + "\n"


README_BEGIN, README_END = "<!-- results:begin", "<!-- results:end -->"


def render_readme_block(data: dict, sources: Sources) -> list[str]:
    """The README's results table: one row per [[row]] of docs/data/readme.toml (what, paper, ours, source)."""
    lines = [f"{README_BEGIN}: generated by `{RENDER}` from docs/data/readme.toml and the result files it "
             "names; edit those, not this table -->",
             "", "| | paper (CARLA) | garage-mj (MuJoCo) | where it comes from |", "|---|---|---|---|"]
    for i, row in enumerate(data["row"]):
        files = ", ".join(f"`docs/{f}`" for f in row.get("files", []))
        for f in row.get("files", []):
            sources.data(f)  # a named file must exist and read
        source = "; ".join(x for x in (_one_line(row.get("source", "")), files) if x)
        if not row.get("what") or not row.get("ours"):
            raise PageError(f"docs/data/readme.toml row {i + 1} has no what or ours: write both")
        cells = [row["what"], row.get("paper", ""), row["ours"], source]
        lines.append("| " + " | ".join(_one_line(sources.fill(c)) for c in cells) + " |")
    return [*lines, "", README_END]


def splice_readme(readme: str, data: dict, sources: Sources) -> str:
    """README.md with the text between its results markers replaced by the rendered table."""
    begin, end = readme.find(README_BEGIN), readme.find(README_END)
    if begin < 0 or end < begin:
        raise PageError(f"README.md has no {README_BEGIN} ... {README_END} block: put the two markers "
                        "where the results table goes")
    return readme[:begin] + "\n".join(render_readme_block(data, sources)) + readme[end + len(README_END):]


@dataclass(frozen=True)
class Page:
    """A rendered page: OUT (under the root) from docs/data/DATA.toml; a spliced page keeps its text outside
    the rendered block."""

    data: str
    out: str
    render: Callable[[dict, Sources], str] | None
    records: tuple[str, ...]  # the data file's tables whose entries carry files and provenance
    splice: Callable[[str, dict, Sources], str] | None = None  # (page text, data, sources) -> page text


PAGES = (Page("performance", "docs/performance.md", render_performance, ("row",)),
         Page("results", "docs/results.md", render_results, ("section.figure",)),
         Page("readme", "README.md", None, (), splice=splice_readme))


def render(root: Path, page: Page) -> str:
    """The page as its data file and result files render it."""
    data_file = root / "docs" / "data" / f"{page.data}.toml"
    try:
        data = tomllib.loads(data_file.read_text())
    except (OSError, ValueError) as exc:  # TOMLDecodeError, UnicodeDecodeError
        raise PageError(f"docs/data/{page.data}.toml cannot be read ({exc})") from None
    sources = Sources(root / "docs")
    if page.splice:
        try:
            text = (root / page.out).read_text()
        except OSError as exc:
            raise PageError(f"{page.out} cannot be read ({exc})") from None
        return page.splice(text, data, sources)
    return page.render(data, sources)


# --- stamping from git ------------------------------------------------------------------------------

def _git(root: Path, *args: str) -> str:
    out = subprocess.run(["git", *args], cwd=root, capture_output=True, text=True)
    if out.returncode != 0:
        raise PageError(f"git {' '.join(args)} failed: {out.stderr.strip()}")
    return out.stdout.strip()


def _last_change(root: Path, name: str) -> tuple[int, str, str]:
    """(time, date, short commit) of the commit that last changed docs/NAME's content (renames followed)."""
    path = f"docs/{name}"
    if _git(root, "status", "--porcelain", "--", path):
        raise PageError(f"{path} has uncommitted changes: commit it, then run `{RENDER} --stamp`")
    line = _git(root, "log", "-1", "--follow", "--diff-filter=AM", "--format=%ct %cs %h", "--", path)
    if not line:
        raise PageError(f"{path} is not in the git history (a shallow clone?): commit it, or stamp on a full clone")
    t, date, commit = line.split()
    return int(t), date, commit


def _set_field(block: str, key: str, value: str) -> str:
    """A record's text with KEY = "VALUE" (replaced, or added after its files line)."""
    line = f'{key} = "{value}"'
    if re.search(rf"^{key}\s*=.*$", block, re.M):
        return re.sub(rf"^{key}\s*=.*$", line, block, count=1, flags=re.M)
    return re.sub(r"^(files\s*=.*)$", rf"\1\n{line}", block, count=1, flags=re.M)


def stamp(root: Path, page: Page) -> list[str]:
    """Write date and commit from git into the data file's records whose files changed since; what changed."""
    if _git(root, "rev-parse", "--is-shallow-repository") == "true":  # its oldest commit "adds" every file
        raise PageError("--stamp needs the full history, and this is a shallow clone: `git fetch --unshallow`")
    data_file = root / "docs" / "data" / f"{page.data}.toml"
    text = data_file.read_text()
    sources, changed = Sources(root / "docs"), []
    # A record's text runs from its [[table]] line to the next [[...]] line; files = [...] is on one line.
    blocks = re.split(r"(?m)^(?=\[\[)", text)
    for i, block in enumerate(blocks):
        head = block.splitlines()[0] if block else ""
        if head.strip("[] ") not in page.records:
            continue
        record = tomllib.loads(re.sub(r"^\[\[.*\]\]", "", block, count=1))
        files = record.get("files", [])
        if not files or all(sources.provenance(f).get("commit") for f in files):
            continue
        _, date, commit = max(_last_change(root, f) for f in files)
        if (record.get("date"), record.get("commit")) != (date, commit):
            blocks[i] = _set_field(_set_field(block, "date", date), "commit", commit)
            changed.append(f"docs/data/{page.data}.toml: {', '.join(files)} -> {date} {commit}")
    data_file.write_text("".join(blocks))
    return changed


def main(argv: list[str] | None = None) -> int:
    """Render, check or stamp the pages; 0 when done, 1 with one line on what is wrong."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--check", action="store_true",
                    help="write nothing; exit 1 naming each page that differs from what its data renders")
    ap.add_argument("--stamp", action="store_true",
                    help="first fill date and commit from git into the data files' records whose result files "
                         "changed since they were stamped (needs the git history), then render")
    ap.add_argument("--root", type=Path, default=ROOT, help="the repository root (default: this checkout)")
    args = ap.parse_args(argv)
    try:
        if args.stamp:
            for line in (c for page in PAGES for c in stamp(args.root, page)):
                print(f"stamped {line}")
        pages = {page.out: render(args.root, page) for page in PAGES}
    except PageError as exc:
        print(f"render_pages: {exc}", file=sys.stderr)
        return 1
    stale = [out for out, text in pages.items()
             if not (args.root / out).is_file() or (args.root / out).read_text() != text]
    if args.check:
        if stale:
            print(f"render_pages: {', '.join(stale)} "
                  f"{'is' if len(stale) == 1 else 'are'} stale (not what docs/data/*.toml and the result files "
                  f"render): run `{RENDER}` and commit the result", file=sys.stderr)
            return 1
        return 0
    for out in stale:
        (args.root / out).write_text(pages[out])
        print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
