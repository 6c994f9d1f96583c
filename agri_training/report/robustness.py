"""Robustness at a glance: the opening success matrix and, per env family, the stress suites' robustness matrix.

Two views of the same entries:

* :func:`glance_table`: per env, every policy's success on every suite (paper, generalization, stress), the
  table the report opens with;
* :func:`robustness_section`: per env with stress suites, a figure of policies x stress levels (success with its
  Wilson interval, collisions marked, the first level below 0.90 boxed) and, below it, one line per policy
  saying where it first drops and why (:func:`agri_training.leaderboard.robustness_lines`).
"""

from __future__ import annotations

import re
import textwrap
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from agri_training import leaderboard as lb
from agri_training.core.stats import wilson_interval
from agri_training.leaderboard.robustness import level_success, policy_name, policy_order

#: Figure width (inches) and resolution: at 100 dpi the PNG is at most 1100 px, the page's text width.
FIGURE_WIDTH = 11.0
FIGURE_DPI = 100
#: Most level columns (and gaps between suites) in one band of the figure before the next suites wrap below.
MAX_COLUMNS = 16
_GAP = 0.3  # blank columns between two suites
_LABEL_WIDTH = 2.5  # inches kept left of the cells for the policy names


def suite_kind(suite: lb.Suite) -> str:
    """``paper``, ``generalization`` or ``stress: <axis>``."""
    if suite.stress:
        return f"stress: {suite.stress}"
    return "generalization" if suite.generalization else "paper"


def _kind_order(suite: lb.Suite) -> int:
    return 2 if suite.stress else 1 if suite.generalization else 0


def _short_names(names: Sequence[str]) -> dict[str, str]:
    """Suite names without the prefix they all share (up to a ``-``): ``greenhouse-corridor`` -> ``corridor``."""
    if len(names) < 2:
        return {n: n for n in names}
    first, last = min(names), max(names)
    k = 0
    while k < min(len(first), len(last)) and first[k] == last[k]:
        k += 1
    cut = first[:k].rfind("-") + 1
    return {n: n[cut:] or n for n in names}


def _rate(entry: Mapping[str, Any]) -> tuple[int, int]:
    pooled = [level_success(level) for level in entry["levels"]]
    return sum(k for k, _ in pooled), sum(n for _, n in pooled)


def _anchor(text: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-")


def glance_table(env_id: str, shown: Sequence[tuple[lb.Suite, Mapping[str, Any]]]) -> list[str]:
    """Markdown: one row per policy, one column per suite of the env, each cell its success rate.

    Suites are ordered paper, generalization, stress; a stress cell pools its levels and adds the worst level's
    rate after a ``▾``. A rate below :data:`~agri_training.leaderboard.SUCCESS_FLOOR` is bold (a stress cell: its
    worst level's); ``-``: no entry.

    Args:
        env_id: The env.
        shown: ``(suite, entry)`` pairs of the report (other envs' are skipped).

    Returns:
        The table's lines (empty when the env has no entry).
    """
    mine = [(s, e) for s, e in shown if s.env_id == env_id]
    if not mine:
        return []
    suites = sorted({s.name: s for s, _ in mine}.values(), key=lambda s: (_kind_order(s), s.name))
    short = _short_names([s.name for s in suites])
    entries = {(s.name, e["policy"]["name"]): e for s, e in mine}
    head = ["policy"] + [f"[{short[s.name]}](#{_anchor(f'{s.name} (v{s.version})')})" for s in suites]
    kinds = ["*suite kind*"] + [f"*{suite_kind(s)}*" for s in suites]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head), "| " + " | ".join(kinds) + " |"]

    def below(k: int, n: int) -> bool:
        return k / n < lb.SUCCESS_FLOOR - 1e-9

    for name, learned, privileged in policy_order([e for _, e in mine]):
        cells = [policy_name(name, learned, privileged)]
        for s in suites:
            entry = entries.get((s.name, name))
            k, n = _rate(entry) if entry else (0, 0)
            if not n:
                cells.append("-")
                continue
            cell, low = f"{k / n:.2f}", below(k, n)
            if s.stress and entry is not None:
                worst = min((level_success(lv) for lv in entry["levels"]), key=lambda kn: kn[0] / max(kn[1], 1))
                cell += f" ▾{worst[0] / worst[1]:.2f}"
                low = below(*worst)
            cells.append(f"**{cell}**" if low else cell)
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def figure_name(env_id: str) -> str:
    """The robustness matrix's file name: ``robustness-greenhouse-nav.png`` (no version: it follows renames)."""
    family = re.sub(r"(?<=[a-z0-9])(?=[A-Z])", "-", lb.env_family(env_id)).replace("_", "-").lower()
    return f"robustness-{family}.png"


def _bands(suites: Sequence[lb.Suite]) -> list[list[lb.Suite]]:
    """Suites split into bands of at most :data:`MAX_COLUMNS` level columns (a wider suite gets its own)."""
    bands: list[list[lb.Suite]] = [[]]
    used = 0.0
    for s in suites:
        width = len(s.levels()) + (_GAP if bands[-1] else 0.0)
        if bands[-1] and used + width > MAX_COLUMNS:
            bands.append([])
            used, width = 0.0, len(s.levels())
        bands[-1].append(s)
        used += width
    return bands


def _column_labels(suite: lb.Suite) -> tuple[str, list[str]]:
    """A suite's group header and its level labels: one argument -> its values; several -> one per line."""
    assert suite.sweep is not None
    names, rows = suite.sweep
    # the arguments wrapped to the group's width (about 11 characters a column), so that groups never overlap
    wrapped = textwrap.fill(f"({', '.join(names)})", width=max(14, 11 * len(rows)))
    header = f"{suite.stress or suite.name}\n{wrapped}"
    if len(names) == 1:
        return header, [_short(row[0]) for row in rows]
    return header, ["\n".join(_short(v) for v in row) for row in rows]


def _short(value: Any, most: int = 12) -> str:
    """A level value as a column label: long ones (a map's path) cut to ``most`` characters."""
    text = str(value)
    return text if len(text) <= most else text[: most - 1] + "…"


def robustness_figure(
    env_id: str, suites: Sequence[lb.Suite], shown: Sequence[tuple[lb.Suite, Mapping[str, Any]]], out_dir: Path
) -> str | None:
    """Draw the env's robustness matrix (policies x stress levels) into ``out_dir``; its file name, or None.

    Each cell: the success rate, its 95 % Wilson interval below it, the colour of the rate (red 0 .. green 1),
    ``×n`` in the corner when n episodes crashed; the first level below the floor of each row and suite is
    boxed. Scripted policies above the line, learned ones below; privileged ones carry ``(P)``.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import TwoSlopeNorm
    from matplotlib.patches import Rectangle

    stress = lb.stress_suites(suites, env_id)
    entries = {(s.name, e["policy"]["name"]): e for s, e in shown if s.stress and s.env_id == env_id}
    stress = [s for s in stress if any(name == s.name for name, _ in entries)]
    if not stress:
        return None
    policies = policy_order(list(entries.values()))
    bands = _bands(stress)
    n_rows = len(policies)
    cell_h = 0.42  # inches
    # per band: the level labels (one line per swept argument), then the two-line suite header above them
    label_h = [0.12 + 0.12 * max(len(s.sweep[0]) if s.sweep else 1 for s in band) for band in bands]
    header_lines = [max(_column_labels(s)[0].count("\n") + 1 for s in band) for band in bands]
    header_h = [h + 0.15 + 0.15 * lines for h, lines in zip(label_h, header_lines, strict=True)]
    title_h, cells_h, gap_h = 0.55, cell_h * n_rows, 0.3
    total = title_h + sum(header_h) + len(bands) * cells_h + (len(bands) - 1) * gap_h + 0.1
    fig = plt.figure(figsize=(FIGURE_WIDTH, total))
    cmap = plt.get_cmap("RdYlGn")
    # the floor is the colour scale's midpoint (yellow): every rate below it reads orange to red
    norm = TwoSlopeNorm(vmin=0.0, vcenter=lb.SUCCESS_FLOOR, vmax=1.0)
    width_cols = MAX_COLUMNS
    for b, band in enumerate(bands):
        bottom = total - title_h - sum(header_h[: b + 1]) - (b + 1) * cells_h - b * gap_h
        ax = fig.add_axes((_LABEL_WIDTH / FIGURE_WIDTH, bottom / total, 1 - (_LABEL_WIDTH + 0.1) / FIGURE_WIDTH,
                           cells_h / total))  # fmt: skip
        ax.set_xlim(0, width_cols)
        ax.set_ylim(n_rows, 0)
        ax.axis("off")
        x = 0.0
        for suite in band:
            header, labels = _column_labels(suite)
            ax.text(x + len(labels) / 2, -(label_h[b] + 0.06) / cell_h, header, ha="center", va="bottom", fontsize=8,
                    fontweight="bold")  # fmt: skip
            for j, label in enumerate(labels):
                longest = max(len(line) for line in label.split("\n"))  # a word like "greenhouse" fills its cell
                ax.text(x + j + 0.5, -0.12, label, ha="center", va="bottom", fontsize=7 if longest <= 8 else 5.5)
            for i, (name, _, _) in enumerate(policies):
                entry = entries.get((suite.name, name))
                drop = lb.first_drop(suite, entry) if entry else None
                for j in range(len(labels)):
                    level = entry["levels"][j] if entry and j < len(entry["levels"]) else None
                    k, n = level_success(level) if level else (0, 0)
                    if not n:
                        ax.add_patch(Rectangle((x + j, i), 1, 1, facecolor="#e6e6e6", edgecolor="white", lw=1.5))
                        ax.text(x + j + 0.5, i + 0.5, "-", ha="center", va="center", fontsize=8, color="#777777")
                        continue
                    rate = k / n
                    rgba = cmap(0.05 + 0.85 * float(norm(rate)))
                    ax.add_patch(Rectangle((x + j, i), 1, 1, facecolor=rgba, edgecolor="white", lw=1.5))
                    dark = 0.299 * rgba[0] + 0.587 * rgba[1] + 0.114 * rgba[2] < 0.5
                    colour = "white" if dark else "black"
                    lo, hi = wilson_interval(k, n)
                    ax.text(x + j + 0.5, i + 0.42, f"{rate:.2f}", ha="center", va="center", fontsize=8.5,
                            fontweight="bold", color=colour)  # fmt: skip
                    ax.text(x + j + 0.5, i + 0.78, f"{lo:.2f}-{hi:.2f}", ha="center", va="center", fontsize=5.5,
                            color=colour)  # fmt: skip
                    crashes = sum(bool(e.get("collision")) for e in level["episodes"])  # type: ignore[index]
                    if crashes:
                        ax.text(x + j + 0.97, i + 0.06, f"×{crashes}", ha="right", va="top", fontsize=6,
                                color="#7a0000", bbox={"boxstyle": "round,pad=0.1", "fc": "white", "ec": "none",
                                                       "alpha": 0.85})  # fmt: skip
                    if drop is not None and drop.index == j:
                        ax.add_patch(Rectangle((x + j + 0.04, i + 0.04), 0.92, 0.92, fill=False, edgecolor="black",
                                               lw=1.8))  # fmt: skip
            x += len(labels) + _GAP
        for i, (name, learned, privileged) in enumerate(policies):
            label = name + (" (P)" if privileged else "")
            ax.text(-0.15, i + 0.5, label, ha="right", va="center", fontsize=8, style="italic" if learned else "normal")
        learned_from = next((i for i, p in enumerate(policies) if p[1]), None)
        if learned_from:  # a rule between the scripted rows and the learned ones, under the names too
            per_column = (FIGURE_WIDTH - _LABEL_WIDTH - 0.1) / width_cols  # inches
            left = -(_LABEL_WIDTH - 0.1) / per_column
            ax.plot([left, x - _GAP], [learned_from] * 2, color="black", lw=1.0, clip_on=False)
    fig.text(
        0.01,
        1 - 0.1 / total,
        f"{env_id}: success by stress level (95 % Wilson interval below), first level of the axis = env default.\n"
        f"Colour: red 0, yellow {lb.SUCCESS_FLOOR:.2f}, green 1; ×n: n episodes crashed; "
        f"box: first level below {lb.SUCCESS_FLOOR:.2f}; "
        "scripted above the line, learned (italic) below; (P) privileged.",
        ha="left",
        va="top",
        fontsize=8.5,
    )
    name = figure_name(env_id)
    fig.savefig(out_dir / name, dpi=FIGURE_DPI, bbox_inches="tight", pad_inches=0.1)  # never wider than drawn
    plt.close(fig)
    return name


def robustness_section(
    env_id: str, suites: Sequence[lb.Suite], shown: Sequence[tuple[lb.Suite, Mapping[str, Any]]], out_dir: Path
) -> list[str]:
    """Markdown: the env's robustness matrix and, below it, per policy, where it first drops and why.

    Args:
        env_id: The env.
        suites: The report's suites (the env's stress suites are drawn).
        shown: ``(suite, entry)`` pairs of the report.
        out_dir: Report folder; the PNG goes there.

    Returns:
        The section's lines, without heading; empty when the env has no stress suite with an entry.
    """
    name = robustness_figure(env_id, suites, shown, out_dir)
    if name is None:
        return []
    lines = lb.robustness_lines(env_id, suites, [e for s, e in shown if s.env_id == env_id])
    return [
        "Each stress suite sweeps one axis from the env's default (its first level) out to the limits the env's "
        f"configuration allows, on held-out seeds. Below the matrix: where each policy first drops below "
        f"{lb.SUCCESS_FLOOR:.2f} success, and the dominant kind of failure there (crash: a collision or contact; "
        "stall: truncated while the robot stood still; time-out: truncated otherwise, or where the record cannot "
        "tell a stall).",
        "",
        f"![{name}]({name})",
        "",
        *lines,
    ]


def _collisions(level: Mapping[str, Any]) -> tuple[int, int]:
    episodes = level["episodes"]
    return sum(bool(e.get("collision")) for e in episodes), len(episodes)


def _rate_text(k: int, n: int) -> str:
    low, high = wilson_interval(k, n)
    return f"{k / n:.2f} [{low:.2f}, {high:.2f}]"


def own_sensors_section(env_id: str, shown: Sequence[tuple[lb.Suite, Mapping[str, Any]]]) -> list[str]:
    """Markdown: each learned policy that uses nothing privileged against the env's best such scripted policy.

    The scripted side is the non-privileged baseline with the highest success pooled over the suites both ran
    (GreenhouseNav: ``harik-apf``, Hector SLAM on the LIDAR). One row per suite level both ran: success of each with
    its Wilson interval, the difference, collisions; a level where the learned policy trails by more than 0.05
    is marked. Empty when the env has no such pair.
    """
    entries = [(s, e) for s, e in shown if s.env_id == env_id and not e["privileged"]]
    learned = sorted({e["policy"]["name"] for _, e in entries if lb.is_learned(e["policy"])})
    scripted = sorted({e["policy"]["name"] for _, e in entries if not lb.is_learned(e["policy"])})
    if not learned or not scripted:
        return []
    by_name: dict[str, dict[str, tuple[lb.Suite, Mapping[str, Any]]]] = {}
    for suite, entry in entries:
        by_name.setdefault(entry["policy"]["name"], {})[suite.name] = (suite, entry)
    lines = []
    for name in learned:
        mine = by_name[name]

        def pooled(other: str, mine: Mapping[str, Any] = mine) -> float:
            common = [by_name[other][s][1] for s in mine if s in by_name[other]]
            k, n = map(sum, zip(*(_rate(e) for e in common), strict=True)) if common else (0, 0)
            return k / n if n else -1.0

        rival = max(scripted, key=lambda other: (pooled(other), other))
        rows, behind = [], 0
        for suite_name in sorted(mine, key=lambda s: (mine[s][0].stress is not None, s)):
            if suite_name not in by_name[rival]:
                continue
            theirs = by_name[rival][suite_name][1]
            for level, other in zip(mine[suite_name][1]["levels"], theirs["levels"], strict=True):
                (k, n), (k2, n2) = level_success(level), level_success(other)
                gap = k / n - k2 / n2
                mark = "**" if gap < -0.05 - 1e-9 else ""
                behind += bool(mark)
                c, _ = _collisions(level)
                c2, _ = _collisions(other)
                rows.append(
                    f"| {mark}`{level['label']}`{mark} | {_rate_text(k, n)} | {_rate_text(k2, n2)} | {gap:+.2f} | "
                    f"{c / n:.2f} | {c2 / n2:.2f} |"
                )
        if not rows:  # no suite level that both ran
            continue
        verdict = (
            f"trails `{rival}` by more than 0.05 on {behind} of {len(rows)} suite levels (marked)"
            if behind
            else f"within 0.05 of `{rival}` or better on every one of the {len(rows)} suite levels both ran"
        )
        lines += [
            f"`{name}` (learned, from the robot's own sensors) against `{rival}` (the best scripted policy "
            f"that uses nothing privileged): {verdict}. Held-out seeds; success with its 95 % Wilson interval.",
            "",
            f"| suite level | `{name}` success | `{rival}` success | difference | `{name}` collisions | "
            f"`{rival}` collisions |",
            "|---|---|---|---|---|---|",
            *rows,
            "",
        ]
    return lines
