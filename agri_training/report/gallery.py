"""The documentation site's source: a page per env family, a page per policy, and the API reference.

Each env page holds a rendered frame, the env class's docstring, every argument with its default and range
from the config class, the env's scenarios and its registered policies. Each policy page (``policies/``)
says what the policy is, which env and env arguments it needs, whether it is privileged, and carries the
API of the function that builds it and of the class it returns. The API pages (``api/``) are
mkdocstrings directives (``::: module``) over the packages' public modules, rendered from their
docstrings. ``python -m agri_training.report.gallery build/docs`` writes the Markdown and PNGs that
``mkdocs build --strict`` (``mkdocs.yml``, ``make docs``) turns into the site. The argument tables are
read from the config dataclass each env is built on (``env.unwrapped.config``: its fields' ``doc``,
``unit``, ``low``, ``high``, ``choices`` metadata), so they cannot drift from the code.
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import re
import sys
import typing
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

import agri_envs
from agri_baselines import PolicySpec, list_policies
from agri_envs.scenarios import list_scenarios
from agri_training.leaderboard import find_suite, is_learned, load_entries, rank_key
from agri_training.learned.zoo import zoo_training  # (importing zoo registers the shipped learned policies)

#: Env families of the site: (page name, env id, preset ids that share the page).
ENV_PAGES = (
    ("greenhouse-nav", "agri_envs/GreenhouseNav-v2", ()),
    ("greenhouse-coverage", "agri_envs/GreenhouseCoverage-v2", ()),
    ("robot-chain", "robot_chain_v1", ()),
    ("grape-harvest", "agri_envs/GrapeHarvest-v1", ("agri_envs/GrapeHarvestReach-v1",)),
)

#: API reference pages: (page name, title, what it covers, modules rendered from their docstrings).
API_PAGES = (
    (
        "envs",
        "agri_envs",
        "The registry (`make`, the ids), the scenarios and the shared scenes.",
        ("agri_envs", "agri_envs.scenarios", "agri_envs.scenes.greenhouse", "agri_envs.scenes.rosmap"),
    ),
    (
        "sim2d",
        "agri_envs.sim2d",
        "The 2D engine the rover, the coverage robot and the chain share: world, robots, sensors, maps, planning.",
        (
            "agri_envs.sim2d.world",
            "agri_envs.sim2d.diff_drive",
            "agri_envs.sim2d.sensors",
            "agri_envs.sim2d.odometry",
            "agri_envs.sim2d.gridmap",
            "agri_envs.sim2d.astar",
            "agri_envs.sim2d.polyline",
        ),
    ),
    (
        "baselines",
        "agri_baselines",
        "The papers' controllers as policies (the registry), and the pure algorithms behind them.",
        (
            "agri_baselines",
            "agri_baselines.harik_apf",
            "agri_baselines.hector_slam",
            "agri_baselines.gonzalez",
            "agri_baselines.gonzalez_planner",
            "agri_baselines.gonzalez_policies",
            "agri_baselines.apoorva_chain",
            "agri_baselines.luo_apf",
        ),
    ),
    (
        "evaluation",
        "agri_training.evaluation",
        "Evaluate any policy on any env: requests, the episode loop, campaigns, the worker pool, clips.",
        (
            "agri_training.api",
            "agri_training.evaluation.reference",
            "agri_training.evaluation.policies",
            "agri_training.evaluation.evaluate",
            "agri_training.evaluation.episode",
            "agri_training.evaluation.parallel",
            "agri_training.evaluation.video",
        ),
    ),
    (
        "datasets",
        "agri_training.datasets",
        "Minari datasets of any policy on any env (agri dataset): the request, the format, the step recorder.",
        ("agri_training.datasets", "agri_training.core.datasets", "agri_training.evaluation.recording"),
    ),
    (
        "leaderboard",
        "agri_training.leaderboard",
        "Pinned suites, entries, verify and LEADERBOARD.md (format: docs/leaderboard.md in the repository).",
        ("agri_training.leaderboard.suites", "agri_training.leaderboard.entries", "agri_training.leaderboard.markdown"),
    ),
    (
        "learned",
        "agri_training.learned and training",
        "Training with SB3, the CPU-independent inference of learned policies, the zoo, the learned harvester.",
        (
            "agri_training.train",
            "agri_training.learned.policy",
            "agri_training.learned.inference",
            "agri_training.learned.onnx_policy",
            "agri_training.learned.sb3_zip",
            "agri_training.learned.torch_zip",
            "agri_training.learned.sidecar",
            "agri_training.learned.zoo",
            "agri_training.learned.harvest",
        ),
    ),
)

#: The repository's docs/ folder: the hand-written guides the site carries, and its stylesheet.
DOCS_DIR = Path(__file__).resolve().parents[2] / "docs"

#: The guides (``docs/NAME.md``, in mkdocs.yml's nav in this order): (file, title, what it covers).
GUIDES = (
    ("install.md", "Install and set up", "what `make report`, `make test`, `make docs` install and run, how long"),
    ("usage.md", "Using the envs", "`gym.make` and `make_vec`, scenes, localization, your own map, the chain, the arm"),
    ("scenarios.md", "Scenarios and baselines", "the papers' experiments as presets, the controllers that drive them"),
    (
        "evaluation.md",
        "Evaluate, watch, record",
        "`agri evaluate` and its JSON, `agri watch`, `agri record`, in Python",
    ),
    ("training.md", "Training and imitation", "`agri train`, hyperparameter YAML, cloning and DAgger, the recipes"),
    ("datasets.md", "Datasets", "Minari datasets of any policy on any env (`agri dataset`), cloning from them"),
    ("leaderboard.md", "Leaderboard and report", "pinned suites, entries, statistics, verify, `agri report`"),
    ("submissions.md", "Submit a policy", "your policy on every suite of its env, verified by CI"),
    ("bring-your-own-policy.md", "Bring your own policy", "train anywhere, export (ONNX, SB3 zip), evaluate, submit"),
    ("scaling.md", "Every core, or a cluster", "worker processes, Ray, sweeps and tuning; where the time goes"),
    ("benchmarks.md", "Benchmarks", "steps per second, planning and SLAM times next to their peers"),
    ("layout.md", "Code layout", "the packages, their layers, and where each part lives"),
)
#: Stylesheet of the site (mkdocs.yml's ``extra_css``): images fit the page; the home page's gallery grid.
EXTRA_CSS = "css/extra.css"

#: The home page's gallery: env page name -> (paper, what it reproduces, the suite whose best scores it shows).
GALLERY = {
    "greenhouse-nav": (
        "Harik & Korsæth 2018",
        "A LIDAR rover drives a loop of waypoints between greenhouse rows among walking people, on the true pose, "
        "odometry or its own Hector SLAM (Figs. 6-17: the simulated loop, plant development, the office corridor, "
        "repeatability).",
        "greenhouse-sim-loop",
    ),
    "greenhouse-coverage": (
        "González et al. 2009",
        "The tracked Fitorobot with seven sonars drives every corridor of a Mediterranean greenhouse end to end "
        "without touching the crop: corridors neither straight nor equally wide, echoes slipping into the foliage.",
        "coverage-almeria",
    ),
    "robot-chain": (
        "Apoorva et al. 2018",
        "A chain of robots (PettingZoo) follows its leader along an A* path across an office to the goal, around "
        "obstacles dropped on the way: ghost robot, sonar potential field, elastic strip.",
        "chain-office",
    ),
    "grape-harvest": (
        "Luo et al. 2018",
        "A 6-DOF arm (pybullet) cuts 2-5 grape clusters at their peduncles without touching their anti-collision "
        "boxes, and returns home (Table 2: energy-optimal order, APF path points).",
        "grape-table2",
    ),
}

INDEX = """\
# agri_envs

Gymnasium / PettingZoo environments for agricultural robots, with the controllers of four papers as scripted
baselines and learned policies (stable-baselines3) benchmarked against them on pinned, held-out suites whose
every number CI re-computes. Each env below opens its page: a frame, the contract (spaces, rewards, episode
end), every argument with its default and range, its scenarios and policies.
"""


def best_scores(suite_name: str, entries: Sequence[Mapping[str, Any]]) -> dict[str, Mapping[str, Any] | None]:
    """The first scripted and the first learned entry of a suite in the leaderboard's ranking (or None).

    Scripted: a registered baseline; learned: every other kind (a zoo policy, a run, an ONNX file, an SB3 zip, ...).
    """
    rank_by = find_suite(suite_name).rank_by
    ranked = sorted(
        (e for e in entries if e["suite"]["name"] == suite_name),
        key=lambda e: (rank_key(e, rank_by), e["policy"]["name"]),
    )
    return {
        kind: next((e for e in ranked if is_learned(e["policy"]) == (kind == "learned")), None)
        for kind in ("scripted", "learned")
    }


def _score(entry: Mapping[str, Any] | None) -> str:
    if entry is None:
        return "none yet"
    s = entry["summary"]
    low, high = s["success_rate_ci"]
    mark = " (privileged)" if entry["policy"].get("privileged") else ""
    name = entry["policy"]["name"]
    return f"[`{name}`](policies/{name}.md){mark} {s['success_rate']:.2f} [{low:.2f}, {high:.2f}]"


def index_page(entries: Sequence[Mapping[str, Any]]) -> str:
    """The home page: a gallery of the envs (frame, paper, best scores) with the guides beside it."""
    cards = []
    for name, env_id, _ in ENV_PAGES:
        paper, what, suite = GALLERY[name]
        best = best_scores(suite, entries)
        episodes = next((e["summary"]["episodes"] for e in entries if e["suite"]["name"] == suite), 0)
        cards += [
            '<div class="env-card" markdown="1">',
            "",
            f"### [{env_id.split('/')[-1]}]({name}.md)",
            "",
            f"[![{env_id} at reset]({name}.png)]({name}.md)",
            "",
            f"`{env_id}` · **{paper}.** {what}",
            "",
            f"Success on `{suite}` ({episodes} held-out episodes, 95 % interval): best scripted "
            f"{_score(best['scripted'])}; best learned {_score(best['learned'])}.",
            "",
            "</div>",
        ]
    guides = [f"- [{title}]({page}): {what}" for page, title, what in GUIDES]
    return "\n".join(
        [
            INDEX,
            '<div class="row" markdown="1">',
            '<div class="col-lg-8" markdown="1">',
            "",
            "## Environments",
            "",
            '<div class="env-gallery" markdown="1">',
            *cards,
            "</div>",
            "</div>",
            '<div class="col-lg-4" markdown="1">',
            "",
            "## Guides",
            "",
            *guides,
            "",
            "## Reference",
            "",
            "- [Policies](policies/index.md): every scripted and learned policy, what it needs, how it was trained",
            "- [Python API](api/index.md): rendered from the docstrings",
            "",
            "Scores are read from the committed leaderboard entries (`leaderboard/entries/`) when the site is built: "
            "the first scripted and the first learned policy in the suite's ranking.",
            "",
            "</div>",
            "</div>",
            "",
        ]
    )


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
            f"| `{p.name}` | {_kind(p)} | {'yes' if p.privileged else 'no'} | {_cell(p.description)} |"
            for p in policies
        ]
        lines.append("")
    return "\n".join(lines)


def _kind(spec: PolicySpec) -> str:
    """``baseline``, or ``learned (how)``: how it was trained, from its zoo folder's config."""
    return f"learned ({zoo_training(spec.name)})" if spec.learned else "baseline"


def _qualified(obj: Any) -> str:
    return f"{obj.__module__}.{obj.__qualname__}"


def policy_page(spec: PolicySpec) -> str:
    """A policy's page: what it is, what it needs, and the API of its factory and of the class it returns."""
    module, attr = spec.entry_point.split(":")
    factory = getattr(importlib.import_module(module), attr)
    kind = _kind(spec) if spec.learned else "scripted baseline"
    needs = ", ".join(f"`{k}={v!r}`" for k, v in spec.env_kwargs.items()) or "none beyond the suite's"
    env_page_name = next((n for n, e, aliases in ENV_PAGES if spec.env_id in (e, *aliases)), None)
    env_link = f"[`{spec.env_id}`](../{env_page_name}.md)" if env_page_name else f"`{spec.env_id}`"
    lines = [
        f"# {spec.name}",
        "",
        spec.description + ("." if spec.description and not spec.description.endswith(".") else ""),
        "",
        "| | |",
        "|---|---|",
        f"| env | {env_link} |",
        f"| kind | {kind} |",
        f"| privileged | {'yes: it uses what a real robot lacks (see below)' if spec.privileged else 'no'} |",
        f"| env arguments it needs | {_cell(needs)} |",
        f"| evaluate | `agri evaluate --env {spec.env_id} --policy {spec.name} --episodes 20 --out result.json` |",
        f"| watch | `agri record --env {spec.env_id} --policy {spec.name} --seed 0 --every 2 --scale 0.5 "
        "--out clip.mp4` (a small clip: every 2nd frame at half size) |",
    ]
    if spec.train_command:
        lines.append(f"| trained with | `{_cell(spec.train_command)}` |")
    lines += ["", "## How it works", ""]
    returned = typing.get_type_hints(factory).get("return")
    made = [factory] + ([returned] if inspect.isclass(returned) else [])
    for obj in made:
        summary = inspect.cleandoc(obj.__doc__ or "").split("\n\n")
        text = " ".join(p.replace("\n", " ") for p in summary if not re.match(r"^(Args|Returns|Raises|Example)", p))
        lines += [f"[`{obj.__qualname__}`][{_qualified(obj)}] (API reference): {_docstring_inline(text)}", ""]
    return "\n".join(lines)


def _docstring_inline(text: str) -> str:
    """A docstring's prose as Markdown: reST roles (``:class:`x```) as code, double backticks as single."""
    text = re.sub(r":[a-z]+:`~?([^`]+)`", lambda m: f"`{m.group(1).split('.')[-1]}`", text)
    return text.replace("``", "`")


def api_page(title: str, what: str, modules: tuple[str, ...]) -> str:
    """An API reference page: mkdocstrings renders each module's public names from their docstrings."""
    lines = [f"# {title}", "", what, ""]
    for module in modules:
        lines += [f"::: {module}", "    options:", "      heading_level: 2", ""]
    return "\n".join(lines)


def build_docs_source(out_dir: Path) -> list[Path]:
    """Write the site's Markdown pages and frames into ``out_dir``; return the pages."""
    out_dir.mkdir(parents=True, exist_ok=True)
    pages = []
    for name, env_id, aliases in ENV_PAGES:
        path = out_dir / f"{name}.md"
        path.write_text(env_page(name, env_id, aliases, out_dir))
        pages.append(path)
    index_path = out_dir / "index.md"
    index_path.write_text(index_page(load_entries()))
    (out_dir / "policies").mkdir(exist_ok=True)
    listing = ["# Policies", "", "| policy | env | kind | privileged | what it is |", "|---|---|---|---|---|"]
    for spec in list_policies():
        path = out_dir / "policies" / f"{spec.name}.md"
        path.write_text(policy_page(spec))
        pages.append(path)
        kind = _kind(spec)
        listing.append(
            f"| [{spec.name}]({spec.name}.md) | `{spec.env_id}` | {kind} | {'yes' if spec.privileged else 'no'} | "
            f"{_cell(spec.description)} |"
        )
    (out_dir / "policies" / "index.md").write_text("\n".join(listing) + "\n")
    (out_dir / "api").mkdir(exist_ok=True)
    listing = ["# Python API", "", "Rendered from the docstrings (mkdocstrings).", "", "| page | what |", "|---|---|"]
    for name, title, what, modules in API_PAGES:
        path = out_dir / "api" / f"{name}.md"
        path.write_text(api_page(title, what, modules))
        pages.append(path)
        listing.append(f"| [{title}]({name}.md) | {_cell(what)} |")
    (out_dir / "api" / "index.md").write_text("\n".join(listing) + "\n")
    for name, _, _ in GUIDES:  # guides written by hand, kept in the repository's docs/
        path = out_dir / name
        path.write_text((DOCS_DIR / name).read_text())
        pages.append(path)
    (out_dir / EXTRA_CSS).parent.mkdir(parents=True, exist_ok=True)
    (out_dir / EXTRA_CSS).write_text((DOCS_DIR / EXTRA_CSS).read_text())
    return [index_path, *pages]


if __name__ == "__main__":
    written = build_docs_source(Path(sys.argv[1] if len(sys.argv) > 1 else "build/docs"))
    print(f"wrote {len(written)} pages under {written[0].parent}")
