"""The baseline evaluation report: run a suite of (env, scenario, policy) entries, write JSON, Markdown, HTML.

Each env contributes its own section (plots of trajectories, paper comparisons) through a hook named in
:data:`SECTION_HOOKS`: ``report_section(results, out_dir) -> markdown``.
"""

from __future__ import annotations

import dataclasses
import html
import importlib
import json
import re
from pathlib import Path
from typing import Any

from agri_baselines import list_policies
from agri_envs.scenarios import Scenario, list_scenarios
from agri_training.evaluate import EvalRequest, evaluate

SECTION_HOOKS = {
    "agri_envs/GreenhouseNav-v1": "agri_training.plots_rover:report_section",
    "agri_envs/GrapeHarvest-v1": "agri_training.plots_arm:report_section",
}


@dataclasses.dataclass(frozen=True)
class SuiteEntry:
    """One evaluation of the report: a policy on an env (scenario) over ``episodes`` seeds from ``seed``."""

    env_id: str
    policy: str
    scenario: str | None = None
    episodes: int = 20
    seed: int = 0


def default_suite(episodes: int | None = None, only_env: str | None = None) -> list[SuiteEntry]:
    """Every registered baseline on every scenario registered for its env (the plain env when there is none).

    Args:
        episodes: Override of each entry's episode count (None: the scenario's default, else 20).
        only_env: Keep only this env id.
    """
    entries = []
    for spec in list_policies():
        if only_env and spec.env_id != only_env:
            continue
        scenarios: list[Scenario | None] = list(list_scenarios(spec.env_id)) or [None]
        for sc in scenarios:
            if sc and any(k in sc.env_kwargs and sc.env_kwargs[k] != v for k, v in spec.env_kwargs.items()):
                continue  # the scenario sets an argument the policy cannot drive (e.g. luo-apf on control="ee")
            n = episodes if episodes is not None else (sc.default_episodes if sc else 20)
            entries.append(SuiteEntry(spec.env_id, spec.name, sc.name if sc else None, n))
    return entries


def _fmt_ci(summary: dict[str, Any], key: str, fmt: str = "{:.2f}") -> str:
    if summary.get(key) is None:
        return "-"
    lo, hi = summary.get(f"{key}_ci", (None, None))
    if lo is None or hi is None:
        return fmt.format(summary[key])
    return f"{fmt.format(summary[key])} [{fmt.format(lo)}, {fmt.format(hi)}]"


def summary_table(results: list[dict[str, Any]]) -> str:
    """Markdown table of the results' headline numbers with 95 % bootstrap intervals."""
    rows = [
        "| policy | scenario | privileged | episodes | success | collisions | time [s] | path [m] | "
        "min clearance [m] |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        s = r["summary"]
        clearance = f"{s['min_clearance']:.3f}" if s.get("min_clearance") is not None else "-"
        label = r.get("label") or r["scenario"] or "default"
        rows.append(
            f"| {r['policy']} | {label} | {'yes' if r['privileged'] else 'no'} | "
            f"{s['episodes']} | {_fmt_ci(s, 'success_rate')} | {_fmt_ci(s, 'collision_rate')} | "
            f"{_fmt_ci(s, 'mean_episode_time', '{:.1f}')} | {_fmt_ci(s, 'mean_path_length', '{:.1f}')} | "
            f"{clearance} |"
        )
    return "\n".join(rows)


def build_report(suite: list[SuiteEntry], out_dir: Path, progress: bool = True) -> Path:
    """Evaluate every suite entry and write ``results/*.json``, ``report.md``, ``report.html`` and plots.

    Returns:
        Path of ``report.md``.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "results").mkdir(exist_ok=True)
    by_env: dict[str, list[dict[str, Any]]] = {}
    for entry in suite:
        result = evaluate(
            EvalRequest(entry.env_id, entry.policy, entry.episodes, entry.seed, entry.scenario), progress=progress
        )
        name = f"{entry.env_id.split('/')[-1]}__{entry.scenario or 'default'}__{entry.policy}.json"
        (out_dir / "results" / name).write_text(json.dumps(result, indent=1))
        by_env.setdefault(entry.env_id, []).extend(result.get("levels", [result]))
    parts = [
        "# agri_envs baseline report",
        "",
        "Every registered scripted baseline, evaluated on seeds 0, 1, ... of its env (and of each of the "
        "env's scenarios). Intervals are 95 % percentile-bootstrap intervals of the mean over episodes. "
        "*Privileged* policies use information a real robot would not have (e.g. the ground-truth pose).",
        "",
    ]
    for env_id, results in by_env.items():
        parts += [f"## {env_id}", "", summary_table(results), ""]
        hook = SECTION_HOOKS.get(env_id)
        if hook:
            module, attr = hook.split(":")
            try:
                section = getattr(importlib.import_module(module), attr)(results, out_dir)
            except ImportError as exc:
                section = f"(plots unavailable: {exc})"
            parts += [section, ""]
        first = results[0]
        parts += [f"Package {first['package_version']}, commit `{first['git_commit'][:10]}`.", ""]
    md_path = out_dir / "report.md"
    md = "\n".join(parts)
    md_path.write_text(md)
    md_path.with_suffix(".html").write_text(markdown_to_html(md, title="agri_envs baseline report"))
    return md_path


def markdown_to_html(md: str, title: str) -> str:
    """Render the report's small Markdown subset (headings, tables, images, lists, paragraphs) as HTML."""

    def inline(text: str) -> str:
        text = html.escape(text)
        text = re.sub(r"!\[([^\]]*)\]\(([^)]+)\)", r'<img alt="\1" src="\2" style="max-width:100%">', text)
        text = re.sub(r"`([^`]+)`", r"<code>\1</code>", text)
        text = re.sub(r"\*\*([^*]+)\*\*", r"<b>\1</b>", text)
        return re.sub(r"\*([^*]+)\*", r"<i>\1</i>", text)

    out = [
        f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>",
        "<style>body{font-family:sans-serif;max-width:1100px;margin:auto;padding:1em}"
        "table{border-collapse:collapse}td,th{border:1px solid #bbb;padding:3px 8px}</style></head><body>",
    ]
    lines = md.splitlines()
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.startswith("#"):
            level = len(line) - len(line.lstrip("#"))
            out.append(f"<h{level}>{inline(line[level:].strip())}</h{level}>")
        elif line.startswith("|"):
            rows = []
            while i < len(lines) and lines[i].startswith("|"):
                rows.append([c.strip() for c in lines[i].strip().strip("|").split("|")])
                i += 1
            out.append("<table>")
            for k, cells in enumerate(rows):
                if k == 1 and all(set(c) <= set("-:") for c in cells):
                    continue
                tag = "th" if k == 0 else "td"
                out.append("<tr>" + "".join(f"<{tag}>{inline(c)}</{tag}>" for c in cells) + "</tr>")
            out.append("</table>")
            continue
        elif line.startswith("- "):
            out.append("<ul>")
            while i < len(lines) and lines[i].startswith("- "):
                out.append(f"<li>{inline(lines[i][2:])}</li>")
                i += 1
            out.append("</ul>")
            continue
        elif line.strip():
            out.append(f"<p>{inline(line)}</p>")
        i += 1
    out.append("</body></html>")
    return "\n".join(out)
