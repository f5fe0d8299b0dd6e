# holoprobe: `make demo` and `make test` work on a fresh machine (they create .venv).
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
DOCS_STAMP := $(VENV)/.installed-docs

.PHONY: install demo test bench lint docs clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[dev,mat73,scale]"
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(PY) -m holoprobe.demo --out out/demo

test: $(STAMP)
	$(PY) -m pytest -n 2 -q

bench: $(STAMP)
	$(PY) benchmarks/run_all.py

# the documentation site (Sphinx + numpydoc + sphinx-gallery) -> docs/_build/html/index.html
$(DOCS_STAMP): $(STAMP)
	$(PY) -m pip install --quiet -e ".[dev,mat73,docs]"
	touch $(DOCS_STAMP)

docs: $(DOCS_STAMP)
	MPLBACKEND=Agg $(PY) -m sphinx -b html -W --keep-going docs docs/_build/html

lint: $(STAMP)
	$(VENV)/bin/ruff check src tests benchmarks examples
	$(VENV)/bin/lint-imports
	$(VENV)/bin/mypy

clean:
	rm -rf $(VENV) out build *.egg-info src/*.egg-info docs/_build docs/api/generated \
		docs/auto_examples docs/sg_execution_times.rst
