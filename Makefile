# The two set-up-and-go targets of README.md. Each creates .venv and installs what it needs when missing.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

TORCH := torch==2.13.0
TORCH_CPU_INDEX := https://download.pytorch.org/whl/cpu

# torch's CPU build first (about 190 MB to download, 750 MB installed): a bare torch requirement pulls the
# CUDA build from PyPI (several GB with its nvidia-* packages). PyTorch's CPU index is used when it answers;
# where it is out of reach (machines that see only PyPI), the default index is used as configured.
$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	if $(BIN)/python -c "import urllib.request as u; u.urlopen('$(TORCH_CPU_INDEX)/torch/', timeout=10)" 2>/dev/null; \
	then $(BIN)/pip install -q "$(TORCH)" --index-url $(TORCH_CPU_INDEX); \
	else echo "PyTorch's CPU index is out of reach: $(TORCH) from the default index"; $(BIN)/pip install -q "$(TORCH)"; fi
	$(BIN)/pip install -q -e ".[train,report,dev,ray,video,docs,datasets]"
	touch $(STAMP)

.PHONY: report test lint bench leaderboard verify docs datasets

# The report page from the committed leaderboard entries, plus fresh runs of whatever is missing or stale.
report: $(STAMP)
	$(BIN)/agri report --out reports/latest

# Static checks, the tests, then the leaderboard's verify on a sample: two episodes of every level of every entry
# re-run on its pinned seed, every summary recomputed from the committed records, LEADERBOARD.md current.
test: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/mypy
	SDL_VIDEODRIVER=dummy SDL_AUDIODRIVER=dummy $(BIN)/python -m pytest -n 2 -q
	$(BIN)/agri leaderboard verify --sample 2

# Every episode of every entry re-run (what the leaderboard workflow runs, one job per env family).
verify: $(STAMP)
	$(BIN)/agri leaderboard verify

# Regenerate the entry of every registered baseline on every suite of its env, and LEADERBOARD.md.
leaderboard: $(STAMP)
	$(BIN)/agri leaderboard submit --all

bench: $(STAMP)
	$(BIN)/pip install -q -e ".[bench]"
	$(BIN)/python benchmarks/bench_greenhouse.py
	$(BIN)/python benchmarks/bench_slam.py
	$(BIN)/python benchmarks/bench_grape.py
	$(BIN)/python benchmarks/bench_vector.py

# The documentation site: a page per env family (frame, docstring, every argument from its config class),
# built by MkDocs in strict mode (a broken link or a missing page fails) into build/site.
# The docs extra comes with the one install of $(STAMP), so nothing is installed again here.
docs: $(STAMP)
	SDL_VIDEODRIVER=dummy $(BIN)/python -m agri_training.report.gallery build/docs
	$(BIN)/python -m mkdocs build --strict

# The reference demonstration datasets (docs/datasets.md): each paper's controller on its env's training
# distribution (GreenhouseNav and GreenhouseCoverage draw a scene per seed from scene_distribution=training; the
# grape vine and the chain's floor are drawn per seed by their default arguments), seeds 50000 and up as the
# pretrain recipes use, written as Minari datasets under MINARI_DATASETS_PATH (default: datasets/ here, which git
# ignores). Each takes well under a few minutes on 2 cores; their sizes are in docs/datasets.md.
MINARI_DATASETS_PATH ?= $(CURDIR)/datasets
DATASET := MINARI_DATASETS_PATH=$(MINARI_DATASETS_PATH) $(BIN)/agri dataset --seed 50000 --overwrite
datasets: $(STAMP)
	$(DATASET) --policy harik-apf-gt --training-distribution --episodes 20
	$(DATASET) --policy gonzalez-deliberative --training-distribution --episodes 50
	$(DATASET) --policy apoorva-chain --episodes 100
	$(DATASET) --policy luo-apf --episodes 200
