
"""The documentation site: a page per env family with its frame and its full argument table, strict build."""

import dataclasses
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

import agri_envs
from agri_training.report.gallery import DOCS_DIR, ENV_PAGES, GALLERY, GUIDES, build_docs_source

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"


def readme_doc_links() -> list[str]:
    """The docs pages README links to (``docs/NAME.md``), in order."""
    return re.findall(r"\]\(docs/([\w-]+\.md)(?:#[\w-]*)?\)", README.read_text())


@pytest.fixture(scope="module")
def site_source(tmp_path_factory):
    out = tmp_path_factory.mktemp("site") / "docs"
    build_docs_source(out)
    return out


@pytest.mark.parametrize(("name", "env_id"), [(name, env_id) for name, env_id, _ in ENV_PAGES])
def test_every_env_page_shows_its_frame_and_every_argument(site_source, name, env_id):
    page = (site_source / f"{name}.md").read_text()
    assert f"![{env_id} at reset]({name}.png)" in page and (site_source / f"{name}.png").stat().st_size > 5_000
    env = agri_envs.make(env_id, **{})
    config = getattr(env, "unwrapped", env).config
    env.close()
    table = page.split("## Arguments of ")[1]
    for f in dataclasses.fields(config):
        assert f"| `{f.name}` |" in table, f.name
    assert "## Description" in page and "## Version History" in page


def test_every_policy_has_a_page_that_links_to_its_api(site_source):
    from agri_baselines import list_policies
    from agri_training.learned import zoo  # noqa: F401  (the shipped learned policies)

    listing = (site_source / "policies" / "index.md").read_text()
    for spec in list_policies():
        page = (site_source / "policies" / f"{spec.name}.md").read_text()
        assert f"[{spec.name}]({spec.name}.md)" in listing
        assert f"| env | [`{spec.env_id}`]" in page and "(API reference)" in page, spec.name
    hybrid = (site_source / "policies" / "gonzalez-hybrid.md").read_text()
    assert "[`GonzalezHybridPolicy`][agri_baselines.gonzalez_policies.GonzalezHybridPolicy]" in hybrid
    assert "::: agri_baselines.gonzalez_policies" in (site_source / "api" / "baselines.md").read_text()


def test_the_home_page_is_a_gallery_with_the_guides_beside_it(site_source):
    index = (site_source / "index.md").read_text()
    for name, env_id, _ in ENV_PAGES:
        paper, _, suite = GALLERY[name]
        card = index.split(f"### [{env_id.split('/')[-1]}]({name}.md)")[1].split("</div>")[0]
        assert f"[![{env_id} at reset]({name}.png)]({name}.md)" in card and paper in card
        # the best scripted and the best learned policy's success on the suite, as the committed entries hold them
        scores = re.findall(r"best (scripted|learned) \[`([\w-]+)`\]\(policies/[\w-]+\.md\)(?: \(privileged\))? "
                            r"(\d\.\d\d) \[", card)  # fmt: skip
        assert [kind for kind, _, _ in scores] == ["scripted", "learned"], card
        for kind, policy, rate in scores:
            entry = json.loads((ROOT / "leaderboard" / "entries" / suite / f"{policy}.json").read_text())
            assert f"{entry['summary']['success_rate']:.2f}" == rate and f"`{suite}`" in card
            assert (entry["policy"]["kind"] == "baseline") == (kind == "scripted")
    for page, title, _ in GUIDES:
        assert f"- [{title}]({page})" in index and (site_source / page).is_file()


def test_every_guide_is_in_the_nav_and_every_docs_page_is_a_guide():
    nav = yaml.safe_load((ROOT / "mkdocs.yml").read_text())["nav"]
    guides = next(item["Guides"] for item in nav if "Guides" in item)
    assert [next(iter(g.values())) for g in guides] == [page for page, _, _ in GUIDES]
    assert sorted(p.name for p in DOCS_DIR.glob("*.md")) == sorted(page for page, _, _ in GUIDES)
    assert len(GUIDES) >= 5


def test_readme_is_a_landing_page():
    text = README.read_text()
    assert len(text.splitlines()) <= 200
    assert "make report   # main job" in text and "make test     # ruff, mypy, pytest" in text and "make verify" in text
    # every docs page it links to is a guide of the site
    links = readme_doc_links()
    assert set(links) == {page for page, _, _ in GUIDES}
    # every held-out number in its policy tables is the committed entry's success rate on the named suite
    rows = re.findall(r"^\| `([\w-]+)` \|.*\| (\d\.\d\d) on `([\w-]+)` \|$", text, flags=re.MULTILINE)
    assert len(rows) >= 20
    for policy, rate, suite in rows:
        entry = json.loads((ROOT / "leaderboard" / "entries" / suite / f"{policy}.json").read_text())
        assert f"{entry['summary']['success_rate']:.2f}" == rate, (policy, suite)


def test_the_site_builds_in_strict_mode(site_source):
    pytest.importorskip("mkdocs")
    pytest.importorskip("mkdocstrings", reason='the API pages need the docs extra: pip install -e ".[docs]"')
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text())
    config.update(docs_dir="docs", site_dir="site")
    cfg = site_source.parent / "mkdocs.yml"
    cfg.write_text(yaml.safe_dump(config))
    run = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(cfg)], capture_output=True, text=True
    )
    assert run.returncode == 0, run.stderr
    assert "WARNING" not in run.stderr
    site = site_source.parent / "site"
    assert (site / "robot-chain" / "index.html").is_file()
    for page in readme_doc_links():  # README's links to the docs pages land on built pages
        assert (site / page.removesuffix(".md") / "index.html").is_file(), page
    assert "max-width: 100%" in (site / "css" / "extra.css").read_text()  # frames and plots fit the page
    # the API reference is rendered from the docstrings, and a policy page's link resolves to it
    api = (site / "api" / "baselines" / "index.html").read_text()
    assert 'id="agri_baselines.gonzalez_policies.GonzalezHybridPolicy"' in api and "lateral_gain" in api
    hybrid = (site / "policies" / "gonzalez-hybrid" / "index.html").read_text()
    assert 'href="../../api/baselines/#agri_baselines.gonzalez_policies.GonzalezHybridPolicy"' in hybrid
