"""TPCAP's 20 published parking cases as park tests (docs/spec.md section 9, "Cases from elsewhere"), driven by the
reference driver and by park_assist.

Each case file (``Case1.csv`` ... ``Case20.csv`` of github.com/libai1943/TPCAP_benchmarks, read from ``--cases``,
default the folder ``GARAGE_MJ_TPCAP_CASES`` names; this repository holds no copy) becomes one park test exactly as
``garage-mj cruise --cases`` runs it (:mod:`garage_mj.driving.cases`): the MuJoCo scene of its obstacle polygons,
TPCAP's car, the stall drawn at its goal, the reference planner's verdict before the drive
(``DEFAULT_PARK``, or ``CASE_PARK`` for a start more than 15 m from the goal; its CPU time by
``time.process_time``), then one drive per driver
from the case's start. Per case and driver it records the verdict, the outcome, the final position and heading
errors, the plan's cusps and the direction changes driven, the planning CPU seconds, and why where it fails (the
planner's or the outcome's reason). Target: the oracle parks >= 18 of the 20.

    GARAGE_MJ_TPCAP_CASES=path/to/TPCAP_benchmarks .venv/bin/python eval/bench_tpcap.py
        # writes docs/bench_tpcap.json (resumable: rows so far in docs/bench_tpcap.rows.jsonl, removed at the end)
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from pathlib import Path

from _provenance import provenance  # eval/_provenance.py: command, date, machine, commit

from garage_mj.driving.cases import case_settings, plan_case, read_case, run_case
from garage_mj.driving.sim.outcomes import NOT_DRIVEN
from garage_mj.scene.case_scene import CASE_PARK, FAR_START, CaseScene
from garage_mj.scene.vehicles import TPCAP_VEHICLE

DRIVERS = ("oracle", "park_assist")
TARGET_PARKED = 18  # of 20, by the oracle


def _num(v: str) -> float | None:
    return float(v) if v not in ("", None) else None


def _case_row(path: Path, plan, cpu: float, far: bool) -> dict:
    return {"case": path.name, "planner_settings": "CASE_PARK" if far else "DEFAULT_PARK", "verdict": plan.verdict, "method": plan.method, "attempt": plan.attempt,
            "plan_cusps": plan.cusps if plan.found else None,
            "plan_length_m": round(plan.length, 2) if plan.found else None,
            "planning_cpu_s": round(cpu, 2), "planner_reason": plan.reason}


def run(cases: list[Path], drivers: tuple[str, ...], rows_path: Path) -> list[dict]:
    done = {}
    if rows_path.is_file():
        for line in rows_path.read_text().splitlines():
            if line.strip():
                r = json.loads(line)
                done[r["case"]] = r
    out = []
    for path in cases:
        if path.name in done and all(d in done[path.name]["drives"] for d in drivers):
            out.append(done[path.name])
            continue
        case = read_case(path)
        t0 = time.process_time()
        plan = plan_case(case)
        far = CaseScene(case).park_config is CASE_PARK
        row = {**_case_row(path, plan, time.process_time() - t0, far), "drives": {}}
        for driver in drivers:
            test = run_case(case, case_settings(driver).resolved("continuous"), plan)
            row["drives"][driver] = {
                "outcome": test["outcome"], "hit": test["hit"], "reason": test["reason"],
                "position_error_m": _num(test["position_error_m"]), "heading_error_deg": _num(test["heading_error_deg"]),
                "direction_changes": _num(test["direction_changes"]), "park_time_s": _num(test["park_time_s"]),
                "park_level": test.get("park_level", ""), "wall_s": test["wall_s"]}
            print(f"{path.name} {driver}: {plan.verdict}, {test['outcome']}: {test['reason'][:160]}", flush=True)
        with rows_path.open("a") as f:
            f.write(json.dumps(row) + "\n")
        out.append(row)
    return out


def summary(rows: list[dict], drivers: tuple[str, ...]) -> dict:
    verdicts = [r["verdict"] for r in rows]
    cpu = [r["planning_cpu_s"] for r in rows]
    out = {"cases": len(rows), **{v: verdicts.count(v) for v in ("feasible", "infeasible", "unproven")},
           "planning_cpu_s": {"median": round(statistics.median(cpu), 2), "max": round(max(cpu), 2),
                              "total": round(sum(cpu), 1)}}
    for d in drivers:
        drives = [r["drives"][d] for r in rows]
        driven = [x for x in drives if x["outcome"] not in NOT_DRIVEN]
        parked = [x for x in drives if x["outcome"] == "success"]
        out[d] = {"parked": len(parked), "of_feasible": len(driven),
                  "outcomes": {k: [x["outcome"] for x in drives].count(k) for k in sorted({x["outcome"] for x in drives})},
                  "mean_position_error_m": round(statistics.mean([x["position_error_m"] for x in parked]), 3)
                  if parked else None,
                  "mean_heading_error_deg": round(statistics.mean([x["heading_error_deg"] for x in parked]), 2)
                  if parked else None}
    out["target"] = f"the oracle parks >= {TARGET_PARKED} of 20"
    out["target_met"] = out["oracle"]["parked"] >= TARGET_PARKED if "oracle" in drivers else None
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", type=Path, default=os.environ.get("GARAGE_MJ_TPCAP_CASES"),
                    help="the folder of TPCAP's Case1.csv ... Case20.csv (default: $GARAGE_MJ_TPCAP_CASES)")
    ap.add_argument("--drivers", nargs="+", default=list(DRIVERS))
    ap.add_argument("--only", type=int, nargs="+", metavar="K",
                    help="run only these cases (their rows join the others' in the rows file; a run of all 20 then "
                         "writes the JSON from them)")
    ap.add_argument("--out", type=Path, default=Path(__file__).resolve().parents[1] / "docs" / "bench_tpcap.json")
    args = ap.parse_args()
    if args.cases is None or not (args.cases / "Case1.csv").is_file():
        raise SystemExit("give --cases DIR (or GARAGE_MJ_TPCAP_CASES) naming a folder of TPCAP's Case1.csv ... "
                         "Case20.csv (a clone of github.com/libai1943/TPCAP_benchmarks)")
    cases = [args.cases / f"Case{k}.csv" for k in (args.only or range(1, 21))]
    drivers = tuple(args.drivers)
    rows = run(cases, drivers, args.out.with_suffix(".rows.jsonl"))
    if args.only:
        return
    result = {"provenance": provenance(), "vehicle": {"name": TPCAP_VEHICLE.name, "length": TPCAP_VEHICLE.length,
                                                      "width": TPCAP_VEHICLE.width, "wheelbase": TPCAP_VEHICLE.wheelbase,
                                                      "max_steer": TPCAP_VEHICLE.max_steer},
              "planner": {"margin": CASE_PARK.margin, "curvature_margin": CASE_PARK.curvature_margin,
                          "CASE_PARK_from_m": FAR_START, "CASE_PARK_escalation_stages": len(CASE_PARK.escalation)},
              "summary": summary(rows, drivers), "cases": rows}
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    args.out.with_suffix(".rows.jsonl").unlink()  # every case is in the JSON: nothing left to resume
    print(json.dumps(result["summary"], indent=2))


if __name__ == "__main__":
    main()
