# hydrapod — make test: create .venv if missing, install with the test extra, run the suite.
PYTHON ?= python3
VENV   ?= .venv
PY      = $(VENV)/bin/python
STAMP   = $(VENV)/.installed

.PHONY: test venv bus-load clean

venv: $(STAMP)

# Reinstall when the package metadata changes; the install is editable, so code edits
# need no reinstall.
$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --upgrade pip
	$(PY) -m pip install -e '.[test]'
	touch $(STAMP)

test: $(STAMP)
	$(PY) -m pytest

bus-load: $(STAMP)
	$(VENV)/bin/hydrapod bus-load --rate-hz 500

clean:
	rm -rf $(VENV) .pytest_cache .hypothesis *.egg-info
