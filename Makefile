# make demo : create .venv, install canest (no extras), run the live demo on virtual CAN (no vehicle, no root)
# make test : also install the SocketCAN test lane (apt), run the tests on the host,
#             then the real-vcan tests inside a User-Mode-Linux guest
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin

.PHONY: demo test test-host test-vcan setup system-deps clean

demo: $(BIN)/canest
	$(BIN)/canest demo

test: test-host test-vcan

test-host: $(VENV)/.test-extras system-deps
	$(BIN)/python -m pytest -m "not socketcan"

test-vcan: $(VENV)/.test-extras system-deps
	tools/vcan-guest -- env CANEST_REQUIRE_SOCKETCAN=1 $(BIN)/python -m pytest -m socketcan

setup: $(VENV)/.test-extras system-deps

system-deps:
	tools/install-system-deps

# the demo needs no extras and no editable install (setuptools prints a warning for one): a plain install,
# redone when a source file changes; the test lane installs the checkout editable, with its extras, on top
$(BIN)/canest: pyproject.toml $(wildcard canest/*.py canest/*/*.py canest/data/*)
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet .
	touch $@

$(VENV)/.test-extras: $(BIN)/canest
	$(BIN)/python -m pip install --quiet -e '.[test,fleet]'
	touch $@

clean:
	rm -rf $(VENV) *.egg-info .pytest_cache
