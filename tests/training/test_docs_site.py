
"""The documentation site: a page per env family with its frame and its full argument table, strict build."""

import dataclasses
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

import agri_envs
from agri_training.report.gallery import ENV_PAGES, build_docs_source

ROOT = Path(__file__).resolve().parents[2]


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
    # the API reference is rendered from the docstrings, and a policy page's link resolves to it
    api = (site / "api" / "baselines" / "index.html").read_text()
    assert 'id="agri_baselines.gonzalez_policies.GonzalezHybridPolicy"' in api and "lateral_gain" in api
    hybrid = (site / "policies" / "gonzalez-hybrid" / "index.html").read_text()
    assert 'href="../../api/baselines/#agri_baselines.gonzalez_policies.GonzalezHybridPolicy"' in hybrid
