# Two commands on a fresh machine: `make demo` and `make test`. Both set everything up first.
# `make install` then puts `servant` on the PATH (a link in BINDIR).
VENV ?= .venv
BINDIR ?= $(HOME)/.local/bin
PY := $(VENV)/bin/python
SHARED ?= ../shared
VMIC := $(SHARED)/scripts/virtual-mic.sh

.PHONY: setup install demo test test-fast bench lint

setup: $(VENV)/.installed

# pip's and setuptools' chatter (an editable install's warning about folders named like the
# package, which is how this checkout is meant to be used) goes to a log, shown only on failure.
$(VENV)/.installed: pyproject.toml
	bash scripts/install-system-packages
	@echo "servant: making the virtual env $(VENV)"
	python3 -m venv $(VENV)
	@echo "servant: installing Python packages into $(VENV) (Textual, NumPy, scikit-learn, OpenCV, BirdNET and the test tools; a minute or two)"
	@$(PY) -m pip install -q --upgrade pip > $(VENV)/install.log 2>&1 || { cat $(VENV)/install.log; exit 1; }
	@$(PY) -m pip install -q -e '.[test]' >> $(VENV)/install.log 2>&1 || { cat $(VENV)/install.log; exit 1; }
	@echo "servant: installed (pip's log: $(VENV)/install.log)"
	touch $@

install: setup
	bash scripts/install-servant $(VENV) $(BINDIR)

# After the demo: how to type `servant` alone, unless it already works.
demo: setup
	@$(VENV)/bin/servant demo; status=$$?; \
	command -v servant >/dev/null || echo "servant: to type \`servant\` in any shell: make install"; \
	exit $$status

# The virtual microphone (a PulseAudio null sink) lets the capture tests record through PortAudio.
test: setup
	@if [ -x $(VMIC) ]; then bash $(VMIC) install || true; fi
	@if [ -x $(VMIC) ] && vmic_env=$$(bash $(VMIC) start 2>/dev/null); then eval "$$vmic_env"; fi; \
	PATH="$(abspath $(VENV))/bin:$$PATH" $(PY) -m pytest -q -p no:cacheprovider --durations=30 -n 2 --dist loadgroup

# The fast lane: the tests without the real data (marked `slow`), without the devices (marked
# `devices`: the virtual microphone, tmux, a controller or sensor board emulator in its own
# process, `servant` in a child process) and without the integration tests (marked `integration`:
# the fuzz suites, and tests that train whole models, walk the demo for minutes or wait on an
# emulated device in real time; tests/conftest.py names them). `make test` runs them all.
test-fast: setup
	PATH="$(abspath $(VENV))/bin:$$PATH" $(PY) -m pytest -q -p no:cacheprovider --durations=10 -n 2 --dist loadgroup -m "not slow and not devices and not integration"

bench: setup
	for b in bench/*.py; do $(PY) $$b || exit 1; done

lint: setup
	$(VENV)/bin/ruff check . && $(VENV)/bin/ruff format --check . && $(VENV)/bin/mypy servant_core servant_tui
