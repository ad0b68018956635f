"""The outputs of an evaluation: ``episodes.csv`` (one row per episode, its factors and every
number), ``summary.json`` and ``summary.md`` (:func:`companion.evaluate.stats.summarize`)."""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path

from companion.evaluate.stats import METRICS
from companion.io import CsvWriter, atomic_write

FACTORS = ("episode", "motion", "group", "side", "sensing", "controller", "seed")


def write_episodes(path: Path, rows: Sequence[dict]) -> None:
    """One line per row: its factors and every number any row has (empty where a row has
    none, e.g. the human companion's numbers of an episode not beside a pair)."""
    numbers = [k for k in dict.fromkeys(k for r in rows for k in r)
               if k not in FACTORS and k != "pair"]
    with CsvWriter(path, [*FACTORS, *numbers]) as out:
        out.add([r.get(k, "") for k in (*FACTORS, *numbers)] for r in rows)


def write_summary(folder: Path, name: str, reference: str, summary: dict,
                  failures: Sequence[tuple[str, list[str]]] = (),
                  criteria: Sequence[str] = ()) -> None:
    """summary.json and summary.md; ``failures``: the episodes that miss the suite's
    ``criteria`` and what they miss."""
    atomic_write(folder / "summary.json", lambda p: p.write_text(
        json.dumps({"suite": name, "reference": reference, "criteria": list(criteria),
                    "failed": [{"episode": e, "missed": m} for e, m in failures],
                    "conditions": summary}, indent=1, allow_nan=True) + "\n",
        encoding="utf-8"))
    atomic_write(folder / "summary.md", lambda p: p.write_text(
        markdown(name, reference, summary) + criteria_text(failures, criteria),
        encoding="utf-8"))


def criteria_text(failures: Sequence[tuple[str, list[str]]], criteria: Sequence[str]) -> str:
    """The suite's pass criteria and the episodes that miss them (empty without criteria)."""
    if not criteria:
        return ""
    lines = [f"## Criteria: {'; '.join(criteria)}", "",
             f"{len(failures)} episode(s) miss them."]
    lines += [f"- {episode}: {', '.join(missed)}" for episode, missed in failures]
    return "\n".join(lines) + "\n"


def _ci(d: dict, scale: float, digits: int) -> str:
    if not math.isfinite(d["median"]):
        return "-"
    text = f"{d['median'] * scale:.{digits}f}"
    if math.isfinite(d["low"]):
        text += f" [{d['low'] * scale:.{digits}f}, {d['high'] * scale:.{digits}f}]"
    return text


#: How each metric is shown: (heading, scale, digits).
SHOWN = {"rms_slot_error_m": ("slot error (cm)", 100.0, 1),
         "rmse_rho_m": ("RMSE rho (cm)", 100.0, 1),
         "rmse_alpha_rad": ("RMSE alpha (rad)", 1.0, 3),
         "min_person_distance_m": ("closest (m)", 1.0, 3)}


def markdown(name: str, reference: str, summary: dict) -> str:
    """Per condition: a table of every controller (median [95 % interval], p90 and worst of
    the slot error, the other metrics' medians, the share of safe episodes) and the paired
    comparison with ``reference``."""
    lines = [f"# {name}", "",
             "Medians with bootstrap 95 % intervals; safe: no robot-caused contact or "
             "protective violation and no obstacle contact, with its exact 95 % interval.", ""]
    for condition, per in summary.items():
        lines += [f"## {condition}", ""]
        head = ["controller", "episodes"] + [SHOWN[m][0] for m in METRICS] + [
            "slot p90 (cm)", "slot worst (cm)", "safe"]
        lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for controller, e in per.items():
            slot = e["metrics"]["rms_slot_error_m"]
            s = e["safe"]
            cells = [controller, str(e["episodes"])]
            cells += [_ci(e["metrics"][m], *SHOWN[m][1:]) for m in METRICS]
            cells += [f"{slot['p90'] * 100:.1f}", f"{slot['worst'] * 100:.1f} "
                      f"({slot['worst_episode']})",
                      f"{s['safe']}/{s['n']} [{s['low']:.1%}, {s['high']:.1%}]"]
            lines.append("| " + " | ".join(cells) + " |")
        paired = [(c, e["paired"]) for c, e in per.items() if "paired" in e]
        if paired:
            lines += ["", f"Paired with `{reference}` on the same episodes (difference "
                      f"controller minus {reference}: median [95 % interval], share of pairs "
                      f"where the controller is better, verdict where the interval excludes "
                      f"0):", "",
                      "| controller | " + " | ".join(SHOWN[m][0] for m in METRICS) + " |",
                      "|" + "---|" * (len(METRICS) + 1)]
            for controller, p in paired:
                cells = [controller]
                for m in METRICS:
                    d = p[m]
                    diff = {"median": d["median_difference"], "low": d["low"], "high": d["high"]}
                    cells.append(f"{_ci(diff, *SHOWN[m][1:])}; {d['share_better']:.0%} better; "
                                 f"{d['verdict']}")
                lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines)
