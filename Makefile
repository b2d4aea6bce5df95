# hapticlab — two commands on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test lint venv clean system-deps

$(PY):
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip

$(STAMP): pyproject.toml | $(PY)
	$(PY) -m pip install --quiet -e '.[test,ui]'
	touch $(STAMP)

venv: $(STAMP)

# Debian packages the tests need (virtual X server, Mesa GL, PortAudio); installed only when missing.
system-deps:
	@if ! command -v Xvfb >/dev/null 2>&1 || ! ldconfig -p | grep -q libportaudio; then \
	  echo "installing Xvfb, Mesa GL, PortAudio and libsndfile from Debian's packages"; \
	  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
	    xvfb libgl1-mesa-dri libglu1-mesa libportaudio2 libasound2 libsndfile1 >/dev/null; \
	fi

demo: $(STAMP)
	$(VENV)/bin/hapticlab demo

lint: $(STAMP)
	$(VENV)/bin/ruff check .

test: $(STAMP) system-deps
	$(VENV)/bin/ruff check .
	$(PY) -m pytest -q

clean:
	rm -rf $(VENV) out .pytest_cache .hypothesis
