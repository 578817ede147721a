"""The HTML report of a run: one self-contained page plus the PNGs, CSVs, MP4s and ``.xosc`` files it links.

No network, no scripts: inline CSS, relative links to images, asset packs and result files, so the
folder can be moved, zipped, mailed or opened from any browser. The data arrives as plain records
(:class:`ReportData`); this module only lays it out. Numbers a person compares are written by one
formatter each (:func:`fmt_difficulty`, :func:`fmt_percent`, :func:`count_noun`), so a garage's
difficulty reads the same in the gallery and in the table.
"""

from __future__ import annotations

import datetime as _dt
import html
import os
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import quote

from garage_mj.core.fsutil import atomic_write

CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:2rem auto;max-width:1100px;
color:#1d232a;padding:0 1rem;line-height:1.45}
h1{font-size:1.7rem;margin-bottom:.2rem}h2{border-bottom:2px solid #e3e7ec;padding-bottom:.2rem;margin-top:2.2rem}
.muted{color:#5d6875}.figs{display:flex;flex-wrap:wrap;gap:1rem}.figs figure{margin:0;flex:1 1 420px}
img{max-width:100%;border:1px solid #d5dbe1;border-radius:4px;background:#fff}
table{border-collapse:collapse;width:100%;font-size:.92rem;margin:.6rem 0}#cruise-table{font-size:.8rem}
#cruise-table th,#cruise-table td{padding:.25rem .35rem}#cruise-table th{vertical-align:bottom;hyphens:auto}
#cruise-table td:nth-child(-n+2){overflow-wrap:anywhere;min-width:6em}
.bleed{width:min(calc(100vw - 3rem),1700px);margin-left:50%;transform:translateX(-50%)}
th,td{border:1px solid #d5dbe1;padding:.3rem .5rem;text-align:right}th{background:#f1f4f7}
td:first-child,th:first-child{text-align:left}
.gallery{display:grid;grid-template-columns:repeat(auto-fill,minmax(250px,1fr));gap:1rem}
.card{border:1px solid #d5dbe1;border-radius:6px;padding:.6rem}.card img{width:100%}
.card p{margin:.3rem 0;font-size:.88rem}.kpi{display:flex;gap:1.5rem;flex-wrap:wrap}
.kpi div{background:#f1f4f7;border-radius:6px;padding:.5rem .9rem}.kpi b{font-size:1.25rem;display:block}
h3{margin:1.4rem 0 .3rem}table.failures td,table.failures th{text-align:left}caption{text-align:left;color:#5d6875;padding:.2rem 0}
ul.reasons>li{margin:.2rem 0}.wide{overflow-x:auto}img.thumb{width:160px}
"""


def fmt_difficulty(value: float) -> str:
    """A garage's difficulty as every part of the report writes it (3 decimals)."""
    return f"{float(value):.3f}"


def fmt_percent(value: float | None) -> str:
    """A rate in percent, e.g. ``100.0%``; ``n/a`` when there is none (no feasible test)."""
    return "n/a" if value is None or value != value else f"{float(value):.1f}%"


#: How outputs name each task of the drive env (``cruise``, ``park``, ``avp``): a run's title, progress and closing lines.
TASK_NOUNS = {"cruise": "cruise", "park": "park", "avp": "AVP"}


PARK_FIGURE_CAPTION = "Success of the feasible tests by level and by maneuver (each bar: successes/feasible)"


#: The top-down pictures a park or AVP run may draw (``cruise --pictures``): the failures its report shows, or every
#: driven test, successes too (:func:`garage_mj.reporting.park.record_park_pictures`).
PICTURE_CHOICES = ("failures", "all")


def task_noun(task: str) -> str:
    """The task as outputs name it: ``cruise``, ``park``, ``AVP`` (``park tests``, ``AVP success``)."""
    return TASK_NOUNS.get(task, task)


def count_noun(n: int, singular: str, plural: str | None = None) -> str:
    """``1 pedestrian``, ``2 pedestrians``; ``plural`` for nouns that do not just add an s."""
    return f"{n} {singular if n == 1 else (plural or singular + 's')}"


@dataclass
class GalleryItem:
    garage_id: int | str
    difficulty: float
    coverage: float
    stalls: int
    preview_png: Path  # top-down picture
    render_png: Path | None = None  # MuJoCo render
    pack_dir: Path | None = None  # the asset pack folder


@dataclass
class ReasonGroup:
    """Failures of one class sharing a reason's wording: the reason with number ranges, and how many."""

    text: str
    count: int


@dataclass
class FailureItem:
    """One failing test the report shows, with its MP4 and OpenSCENARIO file when there are."""

    garage: str
    test: int
    outcome: str
    reason: str
    video: Path | None = None
    xosc: Path | None = None
    picture: Path | None = None  # a park or AVP test's top-down PNG (stalls, plan, driven path)


@dataclass
class ParkTable:
    """A park or AVP run's table: per garage its tests, success and parking metrics, and what success means."""

    label: str  # the run, e.g. "oracle, park tests"
    columns: list[str]
    rows: list[list[object]]
    note: str = ""
    breakdown: list[str] = field(default_factory=list)  # success by level, maneuver and stall angle, one line each
    figure_png: Path | None = None  # the run's success by level and maneuver (park_success.png), under its table


@dataclass
class RunFailures:
    """The failures of one cruise run (a driver, maybe with actors): counts and reasons per class, files."""

    label: str  # e.g. "vision + actors"
    action_type: str  # the action type the driver ran with
    tests_csv: Path  # every test of the run, its outcome and reason
    feasible: int  # feasible tests driven
    counts: dict[str, int] = field(default_factory=dict)  # failure class -> tests
    reasons: dict[str, list[ReasonGroup]] = field(default_factory=dict)  # failure class -> grouped reasons
    shown: list[FailureItem] = field(default_factory=list)


@dataclass
class ReportData:
    title: str
    subtitle: str = ""
    kpis: dict[str, str] = field(default_factory=dict)
    convergence_png: Path | None = None
    heatmap_png: Path | None = None
    gallery: list[GalleryItem] = field(default_factory=list)
    cruise_columns: list[str] = field(default_factory=list)
    cruise_rows: list[list[object]] = field(default_factory=list)
    cruise_note: str = ""  # under the table: what the columns mean
    park_summary: ParkTable | None = None  # several park and AVP runs: success by driver and task, a row per run
    park_tables: list[ParkTable] = field(default_factory=list)  # park and AVP runs only
    park_figure_png: Path | None = None  # a park or AVP run's success by level and maneuver (park_success.png)
    parked: list[FailureItem] = field(default_factory=list)  # successes with a top-down picture (cruise --pictures all)
    failures: list[RunFailures] = field(default_factory=list)
    regression_png: Path | None = None  # success rate vs the paper's difficulty
    regression_route_png: Path | None = None  # success rate vs the route difficulty
    regression_text: str = ""
    notes: list[str] = field(default_factory=list)


def _rel(path: Path | None, out_dir: Path) -> str:
    """``path`` as a link relative to ``out_dir`` (URL-quoted: a ``#`` or ``:`` in a name stays part of the path)."""
    return html.escape(quote(Path(os.path.relpath(Path(path).resolve(), out_dir.resolve())).as_posix()))


def _fmt(v: object) -> str:
    if isinstance(v, float):
        return f"{v:.3f}"
    return html.escape(str(v))


def _figure(path: Path | None, caption: str, out_dir: Path) -> str:
    if path is None:
        return ""
    return (
        f'<figure><img src="{_rel(path, out_dir)}" alt="{html.escape(caption)}">'
        f"<figcaption class=muted>{html.escape(caption)}</figcaption></figure>"
    )


def _link(path: Path | None, text: str, out_dir: Path) -> str:
    return "-" if path is None else f'<a href="{_rel(path, out_dir)}">{html.escape(text)}</a>'


def _thumb(path: Path | None, alt: str, out_dir: Path) -> str:
    """A small picture linking to itself full size; ``-`` when there is none."""
    if path is None:
        return "-"
    src = _rel(path, out_dir)
    return f'<a href="{src}"><img class=thumb src="{src}" alt="{html.escape(alt)}"></a>'


def _park_table(table: ParkTable, index: int | str, out_dir: Path) -> str:
    """One park or AVP run's table (``id=park-table-<index>``, from 1; a str index is the id itself), its note and
    its figure."""
    e = html.escape
    table_id = index if isinstance(index, str) else f"park-table-{index}"
    parts = [f"<h3>{e(table.label)}</h3><div class=wide><table id={table_id}><thead><tr>"]
    parts += [f"<th>{e(c)}</th>" for c in table.columns]
    parts.append("</tr></thead><tbody>")
    parts += ["<tr>" + "".join(f"<td>{_fmt(v)}</td>" for v in row) + "</tr>" for row in table.rows]
    parts.append("</tbody></table></div>")
    if table.breakdown:
        parts.append(f"<ul id=park-breakdown-{index}>" + "".join(f"<li>{e(line)}</li>" for line in table.breakdown)
                     + "</ul>")
    if table.note:
        parts.append(f"<p class=muted>{e(table.note)}</p>")
    if table.figure_png is not None:
        parts.append("<div class=figs>" + _figure(table.figure_png, PARK_FIGURE_CAPTION, out_dir) + "</div>")
    return "".join(parts)


def _run_failures(run: RunFailures, out_dir: Path) -> str:
    """One driver run: failures per class with their grouped reasons, the shown tests with their files."""
    e = html.escape
    failed = sum(run.counts.values())
    parts = [
        f"<h3>{e(run.label)} &middot; {e(run.action_type)} actions</h3>",
        f"<p>{count_noun(failed, 'failure')} in {count_noun(run.feasible, 'feasible test')} &middot; every test, "
        f"its outcome and reason: {_link(run.tests_csv, 'tests.csv', out_dir)}</p>",
    ]
    if run.reasons:
        parts.append("<ul class=reasons>")
        for kind, groups in run.reasons.items():
            lines = "".join(f"<li>{g.count} &times; {e(g.text)}</li>" for g in groups)
            parts.append(f"<li><b>{e(kind.replace('_', ' '))}</b> ({run.counts.get(kind, 0)})<ul>{lines}</ul></li>")
        parts.append("</ul>")
    if run.shown:
        pictures = any(f.picture is not None for f in run.shown)  # a park or AVP run's: a column of its own
        n = len(run.shown)
        which = (f"the first {n} of {failed} failures (all of them in tests.csv)" if failed > n
                 else "the failure" if n == 1 else f"the {n} failures")
        parts.append(f"<div class=wide><table class=failures><caption>{which}</caption><thead><tr><th>garage</th>"
                     "<th>test</th><th>outcome</th><th>reason</th><th>video</th><th>OpenSCENARIO</th>"
                     + ("<th>top-down</th>" if pictures else "") + "</tr></thead><tbody>")
        for f in run.shown:
            parts.append(
                f"<tr><td>{e(f.garage)}</td><td>{f.test}</td><td>{e(f.outcome.replace('_', ' '))}</td>"
                f"<td>{e(f.reason)}</td><td>{_link(f.video, 'MP4', out_dir)}</td>"
                f"<td>{_link(f.xosc, f.xosc.name if f.xosc else '', out_dir)}</td>"
                + (f"<td>{_thumb(f.picture, f'{f.garage} test {f.test} top-down', out_dir)}</td>" if pictures else "")
                + "</tr>"
            )
        parts.append("</tbody></table></div>")
    return "\n".join(parts)


def _parked(items: list[FailureItem], out_dir: Path) -> str:
    """The successes of a park or AVP run with their top-down pictures (``cruise --pictures all``)."""
    e = html.escape
    parts = [f"<h2 id=parked>Successes</h2><div class=wide><table class=failures id=parked-table><caption>"
             f"{count_noun(len(items), 'success')} with a top-down picture</caption><thead><tr><th>garage</th>"
             "<th>test</th><th>reason</th><th>top-down</th></tr></thead><tbody>"]
    parts += [f"<tr><td>{e(f.garage)}</td><td>{f.test}</td><td>{e(f.reason)}</td>"
              f"<td>{_thumb(f.picture, f'{f.garage} test {f.test} top-down', out_dir)}</td></tr>" for f in items]
    parts.append("</tbody></table></div>")
    return "".join(parts)


def render_html(data: ReportData, out_dir: Path) -> str:
    """The report page as a string; image and pack links are relative to ``out_dir``."""
    out_dir = Path(out_dir)
    e = html.escape
    parts = [
        "<!doctype html><html lang=en><head><meta charset=utf-8>",
        "<meta name=viewport content='width=device-width,initial-scale=1'>",
        f"<title>{e(data.title)}</title><style>{CSS}</style></head><body>",
        f"<h1>{e(data.title)}</h1><p class=muted>{e(data.subtitle)} &middot; written "
        f"{_dt.datetime.now().strftime('%Y-%m-%d %H:%M')}</p>",
    ]
    if data.kpis:
        parts.append("<div class=kpi>")
        parts += [f"<div><b>{e(v)}</b>{e(k)}</div>" for k, v in data.kpis.items()]
        parts.append("</div>")
    if data.convergence_png is not None or data.heatmap_png is not None:  # a cruise run's report has neither
        parts.append("<h2 id=generation>Generation</h2><div class=figs>")
        parts.append(_figure(data.convergence_png, "Convergence: episode return, mean over seeds, 95% band", out_dir))
        parts.append(_figure(data.heatmap_png, "Usable garages by difficulty (x) and coverage (y)", out_dir))
        parts.append("</div>")
    if data.gallery:
        parts.append("<h2 id=gallery>Garages</h2><div class=gallery>")
        for g in data.gallery:
            imgs = f'<img src="{_rel(g.preview_png, out_dir)}" alt="garage {e(str(g.garage_id))} top-down">'
            if g.render_png is not None:
                imgs += f'<img src="{_rel(g.render_png, out_dir)}" alt="garage {e(str(g.garage_id))} MuJoCo render">'
            link = ""
            if g.pack_dir is not None:
                link = f' &middot; <a href="{_rel(g.pack_dir, out_dir)}/">asset pack</a>'
            parts.append(
                f"<div class=card>{imgs}<p><b>garage {e(str(g.garage_id))}</b>{link}</p>"
                f"<p>difficulty {fmt_difficulty(g.difficulty)} &middot; coverage {g.coverage:.2f} &middot; "
                f"{g.stalls} stalls</p></div>"
            )
        parts.append("</div>")
    if data.cruise_rows:
        # wider than the text when the window is (.bleed), names wrapping anywhere: the last column stays in view
        parts.append("<h2 id=cruise>Cruise tests</h2><div class='wide bleed'><table id=cruise-table><thead><tr>")
        parts += [f"<th>{e(c)}</th>" for c in data.cruise_columns]
        parts.append("</tr></thead><tbody>")
        for row in data.cruise_rows:
            parts.append("<tr>" + "".join(f"<td>{_fmt(v)}</td>" for v in row) + "</tr>")
        parts.append("</tbody></table></div>")
        if data.cruise_note:
            parts.append(f"<p class=muted>{e(data.cruise_note)}</p>")
    if data.park_tables or data.park_summary is not None:
        parts.append("<h2 id=park>Park tests</h2>")
        if data.park_summary is not None:
            parts.append(_park_table(data.park_summary, "park-summary", out_dir))
        parts += [_park_table(t, k, out_dir) for k, t in enumerate(data.park_tables, 1)]
        if data.park_figure_png is not None:
            parts.append("<div class=figs>" + _figure(data.park_figure_png, PARK_FIGURE_CAPTION, out_dir) + "</div>")
    if data.failures:
        parts.append("<h2 id=failures>Failures</h2>")
        parts += [_run_failures(f, out_dir) for f in data.failures]
    if data.parked:
        parts.append(_parked(data.parked, out_dir))
    if data.regression_png is not None or data.regression_route_png is not None or data.regression_text:
        parts.append("<h2 id=regression>Success rate vs difficulty</h2>")
        if data.regression_text:
            parts.append(f"<p>{e(data.regression_text)}</p>")
        parts.append("<div class=figs>"
                     + _figure(data.regression_png, "Linear regression of success rate on the paper's difficulty", out_dir)
                     + _figure(data.regression_route_png, "Linear regression of success rate on the route difficulty "
                               "(dashed: a calibrated difficulty, success = 100 (1 - x))", out_dir)
                     + "</div>")
    if data.notes:
        parts.append("<h2 id=notes>Notes</h2><ul>" + "".join(f"<li>{e(n)}</li>" for n in data.notes) + "</ul>")
    parts.append("</body></html>")
    return "\n".join(p for p in parts if p)


def write_report(data: ReportData, out_dir: Path, name: str = "report.html") -> Path:
    """Write the page atomically into ``out_dir``; returns its path."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    missing = [
        p
        for p in [data.convergence_png, data.heatmap_png, data.regression_png, data.regression_route_png,
                  data.park_figure_png]
        + [t.figure_png for t in data.park_tables]
        + [g.preview_png for g in data.gallery]
        + [g.render_png for g in data.gallery]
        if p is not None and not Path(p).is_file()
    ]
    if missing:
        raise FileNotFoundError(f"report images missing: {', '.join(str(m) for m in missing)}")
    links = [r.tests_csv for r in data.failures] + [p for r in data.failures for f in r.shown
                                                    for p in (f.video, f.xosc, f.picture)] + [f.picture for f in data.parked]
    missing = [p for p in links if p is not None and not Path(p).is_file()]
    if missing:
        raise FileNotFoundError(f"report links missing: {', '.join(str(m) for m in missing)}")
    path = out_dir / name
    return atomic_write(path, render_html(data, out_dir))
