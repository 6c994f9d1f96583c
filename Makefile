# The two set-up-and-go targets of README.md. Each creates .venv and installs what it needs when missing.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	# CPU build of torch first: a bare torch requirement would pull a multi-GB CUDA build.
	$(BIN)/pip install -q torch==2.13.0
	$(BIN)/pip install -q -e ".[train,report,dev,ray]"
	touch $(STAMP)

.PHONY: report test lint bench leaderboard verify

# The report page from the committed leaderboard entries, plus fresh runs of whatever is missing or stale.
report: $(STAMP)
	$(BIN)/agri report --out reports/latest

# Static checks, the tests, then the leaderboard's verify (re-runs every entry on its pinned seeds).
test: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/mypy
	SDL_VIDEODRIVER=dummy SDL_AUDIODRIVER=dummy $(BIN)/python -m pytest -n 2 -q
	$(BIN)/agri leaderboard verify

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
