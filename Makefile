# Every target builds its own virtual environment in .venv; nothing relies on what is installed.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
COMPILED := $(VENV)/.compiled
DOCS_STAMP := $(VENV)/.docs-installed

.PHONY: install demo test test-all bench lint docs check-install clean

install: $(STAMP) $(COMPILED)

# constraints.txt: the versions the test suite passed with (docs/development.md). The bytecode of
# the installed modules (but the packages' own tests, pip and setuptools, which no run imports)
# and of rkhp's sources is written by compileall on every core (pip writes it one file at a
# time); it must be written here: under PYTHONDONTWRITEBYTECODE no process writes it at import.
$(STAMP): pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet --no-compile -c constraints.txt -e '.[test,distributed]'
	$(PY) -m compileall -q -j 0 -x '/(tests?|pip|setuptools)/' \
		"$$($(PY) -c 'import sysconfig; print(sysconfig.get_path("purelib"))')" rkhp cli
	touch $(STAMP)

# numba's cache filled for the compiled sources as they are, so that no run (and no test process)
# waits for a compile; again after an edit of them (a new cache folder: docs/engine.md)
$(COMPILED): $(STAMP) $(wildcard rkhp/taylor/*.py rkhp/integrators/*.py)
	$(VENV)/bin/rkhp compile
	touch $(COMPILED)

# The main job: the kernels compiled (by install), the paper's Table 1, an exact order check, a
# seeded search that finds the paper's "one stage less than RK4", and a convergence study of the
# RKHP methods on the rigid body.
demo: install
	$(VENV)/bin/rkhp conditions --order 5 --degenerate
	$(VENV)/bin/rkhp verify paper-three-stage
	$(VENV)/bin/rkhp search --stages 3 --degenerate --seed 0 --optimize error
	$(VENV)/bin/rkhp converge rigid-body
	@echo
	@echo "rkhp is installed in $(CURDIR)/$(VENV): run it as $(VENV)/bin/rkhp (e.g. $(VENV)/bin/rkhp --help),"
	@echo "or put it on your PATH for this shell: source $(VENV)/bin/activate"

# The kernels compiled by install: the test processes then never compile the same kernel side by
# side. -n auto: one test process per core (pytest-xdist); --dist worksteal: a process that has
# run its share takes tests queued for the other (docs/development.md); PYTHONHASHSEED=0: the
# docs' rkhp commands run in the test process (docs/_ext/doccode.py) with the hashing of the
# separate process they stand for.
test: install
	PYTHONHASHSEED=0 $(PY) -m pytest -m "not slow" -q -p no:cacheprovider -n auto --dist worksteal

test-all: install $(DOCS_STAMP)
	PYTHONHASHSEED=0 $(PY) -m pytest -q -p no:cacheprovider -n auto --dist worksteal

$(DOCS_STAMP): $(STAMP)
	$(PY) -m pip install --quiet -c constraints.txt -e '.[test,docs]'
	touch $(DOCS_STAMP)

# The documentation site (Sphinx, see docs/index.md): offline, warnings are errors, every
# cross-reference must resolve (-n). Output: docs/_build/html/index.html.
docs: $(DOCS_STAMP)
	$(VENV)/bin/sphinx-build -E -W --keep-going -n -q -b html docs docs/_build/html

# The peers must import: no silent skip. numbalsoda builds from source with a Fortran compiler
# (Debian: apt-get install gfortran; docs/studies.md "Peers").
bench: install
	$(PY) -m pip install --quiet -c constraints.txt -e '.[bench,peers]'
	$(PY) -c "import nodepy.runge_kutta_method, nodepy.rooted_trees, numbalsoda, jax, diffrax"
	for b in benchmarks/*.py; do echo "== $$b"; $(PY) $$b || exit 1; done

lint: install
	$(VENV)/bin/ruff check .

# Installs the project non-editably into a throw-away environment and runs the console script.
check-install:
	rm -rf /tmp/rkhp-check-install && $(PYTHON) -m venv /tmp/rkhp-check-install
	/tmp/rkhp-check-install/bin/pip install --quiet .
	cd /tmp && /tmp/rkhp-check-install/bin/rkhp conditions --order 5 --symmetric --format json > /dev/null
	cd /tmp && /tmp/rkhp-check-install/bin/rkhp verify paper-three-stage
	cd /tmp && /tmp/rkhp-check-install/bin/rkhp tables --format json > /dev/null
	cd /tmp && /tmp/rkhp-check-install/bin/python -c "import rkhp, rkhp_cli, importlib.util as u; assert u.find_spec('cli') is None; print('no top-level cli module: ok')"

clean:
	rm -rf $(VENV) build *.egg-info docs/_build docs/_generated
