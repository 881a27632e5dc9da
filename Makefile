# Two commands do all the set-up on a fresh machine with Python 3.11:
#   make demo   -> .venv + render the demo dataset + its HTML gallery
#   make test   -> .venv + pytest
PYTHON ?= python3.11
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: demo test lint venv clean

venv: $(STAMP)

# Plain pip on purpose: it takes torch/torchvision from this machine's local wheels
# (uv/poetry would download ~3 GB of CUDA wheels instead).
$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install -e '.[test]'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/crackgen generate recipes/demo.toml --out out/demo --resume
	$(BIN)/crackgen inspect out/demo
	@echo "Gallery: $(CURDIR)/out/demo/inspect/index.html"

# Lint (ruff: pyflakes, sorted imports, no relative imports) and the layering contracts
# (import-linter, [tool.importlinter] in pyproject) run first: a broken layer fails CI.
# pytest exits 5 when it collects nothing; that must fail, and it does (non-zero).
test: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/lint-imports
	$(BIN)/python -m pytest -q

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/lint-imports

clean:
	rm -rf $(VENV) out .pytest_cache
