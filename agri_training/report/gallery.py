"""The documentation site's source: one page per env family, with its frame, docstring and arguments.

Each page holds a rendered frame, the env class's docstring, every argument with its default and range
from the config class, the env's scenarios and its registered policies.
``python -m agri_training.report.gallery build/docs`` writes the Markdown and PNGs that ``mkdocs build
--strict`` (``mkdocs.yml``, ``make docs``) turns into the site. The argument tables are read from the
config dataclass each env is built on (``env.unwrapped.config``: its fields' ``doc``, ``unit``, ``low``,
``high``, ``choices`` metadata), so they cannot drift from the code.
"""

from __future__ import annotations

import dataclasses
import inspect
import re
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

import agri_envs
from agri_baselines import list_policies
from agri_envs.scenarios import list_scenarios

#: Env families of the site: (page name, env id, preset ids that share the page).
ENV_PAGES = (
    ("greenhouse-nav", "agri_envs/GreenhouseNav-v2", ()),
    ("greenhouse-coverage", "agri_envs/GreenhouseCoverage-v0", ()),
    ("robot-chain", "robot_chain_v1", ()),
    ("grape-harvest", "agri_envs/GrapeHarvest-v1", ("agri_envs/GrapeHarvestReach-v1",)),
)

INDEX = """\
# agri_envs

Gymnasium / PettingZoo environments for agricultural robots, with the controllers of published papers as
scripted baselines and learned policies (stable-baselines3) benchmarked against them. The README is the
short path in (set-up, `agri` commands); these pages document each env in full.

| env | page |
|---|---|
"""


def _range_text(meta: Mapping[str, Any]) -> str:
    if meta.get("valid"):
        return str(meta["valid"])
    if meta.get("choices"):
        return "one of " + ", ".join(f"`{c!r}`" for c in meta["choices"])
    low, high = meta.get("low"), meta.get("high")
    if low is not None and high is not None:
        return f"[{low}, {high}]"
    if low is not None:
        return f">= {low}"
    if high is not None:
        return f"<= {high}"
    return "any"


def _cell(text: Any) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def argument_table(config: Any) -> list[str]:
    """Markdown table of a config dataclass: argument, default, unit, valid values, description."""
    rows = ["| argument | default | unit | valid | description |", "|---|---|---|---|---|"]
    for f in dataclasses.fields(config):
        default = f.default if f.default is not dataclasses.MISSING else getattr(config, f.name)
        meta = f.metadata
        rows.append(
            f"| `{f.name}` | `{_cell(repr(default))}` | {_cell(meta.get('unit', ''))} | "
            f"{_cell(_range_text(meta))} | {_cell(meta.get('doc', ''))} |"
        )
    return rows


def _docstring_markdown(cls: type) -> str:
    """The class docstring as Markdown: dedented; its ``## Sections`` sit under the page's ``#`` title."""
    doc = inspect.cleandoc(cls.__doc__ or "")
    return re.sub(r"::\n", ":\n", doc)  # reST literal-block markers read as plain colons in Markdown


def env_page(name: str, env_id: str, aliases: tuple[str, ...], out_dir: Path) -> str:
    """Write the env's frame (``NAME.png``) and return its page's Markdown."""
    from PIL import Image

    env = agri_envs.make(env_id, **{"render_mode": "rgb_array"})
    try:
        env.reset(seed=0)
        frame = np.asarray(env.render(), dtype=np.uint8)
        raw = getattr(env, "unwrapped", env)
        config, cls = raw.config, type(raw)
    finally:
        env.close()
    Image.fromarray(frame).save(out_dir / f"{name}.png")
    ids = ", ".join(f"`{i}`" for i in (env_id, *aliases))
    scenarios = list_scenarios(env_id)
    lines = [
        f"# {env_id.split('/')[-1]}",
        "",
        f"Ids: {ids}. Rendered at `reset(seed=0)` with every argument at its default:",
        "",
        f"![{env_id} at reset]({name}.png)",
        "",
        _docstring_markdown(cls),
        "",
        f"## Arguments of `{type(config).__name__}`",
        "",
        "Every field is a `gym.make` argument (`parallel_env` for the chain); an unknown name or a value out "
        "of range raises a `ValueError` that names it.",
        "",
        *argument_table(config),
        "",
    ]
    if scenarios:
        lines += ["## Scenarios", "", "| scenario | what it reproduces |", "|---|---|"]
        lines += [f"| `{s.name}` | {_cell(s.description)} |" for s in scenarios]
        lines.append("")
    policies = [p for p in list_policies() if p.env_id in (env_id, *aliases)]
    if policies:
        lines += ["## Policies", "", "| policy | kind | privileged | what it is |", "|---|---|---|---|"]
        lines += [
            f"| `{p.name}` | {'learned (' + str(p.algo) + ')' if p.learned else 'baseline'} | "
            f"{'yes' if p.privileged else 'no'} | {_cell(p.description)} |"
            for p in policies
        ]
        lines.append("")
    return "\n".join(lines)


def build_docs_source(out_dir: Path) -> list[Path]:
    """Write the site's Markdown pages and frames into ``out_dir``; return the pages."""
    out_dir.mkdir(parents=True, exist_ok=True)
    pages = []
    index = [INDEX.rstrip("\n")]
    for name, env_id, aliases in ENV_PAGES:
        path = out_dir / f"{name}.md"
        path.write_text(env_page(name, env_id, aliases, out_dir))
        pages.append(path)
        index.append(f"| `{env_id}` | [{name}]({name}.md) |")
    index_path = out_dir / "index.md"
    index_path.write_text("\n".join(index) + "\n")
    return [index_path, *pages]


if __name__ == "__main__":
    written = build_docs_source(Path(sys.argv[1] if len(sys.argv) > 1 else "build/docs"))
    print(f"wrote {len(written)} pages under {written[0].parent}")
