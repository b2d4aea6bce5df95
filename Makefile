# hapticlab — two commands on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test check lint venv clean system-deps screens contract docs firmware-test

$(PY):
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip

# setup.py builds the link's native threads (firmware/src/hostlink.c) with the package; the
# PsychoPy plugin (its own distribution, plugins/psychopy-hapticlab) installs beside it
PLUGIN := plugins/psychopy-hapticlab
# PsychoPy's Builder app, for the tests' screenshots of the plugin's dialogs: beside the
# environment (it requires wxPython, which PyPI has for Linux only as source; Debian's
# python3-wxgtk4.0 is used instead), with the packages it imports that PsychoPy does not
BUILDER_APP := psychopy-app==2026.2.1 python-gitlab gitpython gitdb smmap pytz future \
               requests-toolbelt
# The bytecode is compiled on both cores (pip compiles on one: 30 of an install's 66 s).
# It must be compiled: where PYTHONDONTWRITEBYTECODE is set (as on the machine that measured
# the gate), nothing is ever compiled on import, and every process compiles again all it
# imports (without it, the two-worker gate took 25 min 39 s instead of 21 min 43 s).
$(STAMP): pyproject.toml setup.py firmware/src/hostlink.c firmware/include/hl_hostlink.h \
          $(PLUGIN)/pyproject.toml | $(PY)
	$(PY) -m pip install --quiet --no-compile -e '.[test,ui,lsl,docs]' -e $(PLUGIN)
	$(PY) -m pip install --quiet --no-compile --no-deps --upgrade --target $(VENV)/psychopy-app \
	  $(BUILDER_APP)
	$(PY) -m compileall -q -j 2 $(VENV)/lib $(VENV)/psychopy-app > $(VENV)/compileall.log \
	  || echo "compileall: the modules in $(VENV)/compileall.log did not compile (pip too" \
	    "leaves them without bytecode); a process that imports one compiles it"
	touch $(STAMP)

venv: $(STAMP)

# Debian packages the tests need: a virtual X server, Mesa GL, PortAudio, xdotool (a person's
# keys into the participant's window), tmux (the operator's terminal), a monospace font, and
# the X libraries Qt needs for PsychoPy's participant-information dialog; installed only
# when missing; chromium renders report.html headless for its screenshot test; gcc builds the
# firmware's host build, arm-none-eabi-gcc (with newlib) its Cortex-M build, and
# qemu-system-arm runs that on an emulated STM32F405; clang-14 and libFuzzer fuzz the
# firmware's receive path and command executor; strace shows where liblsl sends (the LSL
# tests); g++ and libusb-1.0-0-dev are what a lab's Force Dimension build needs besides its
# SDK (check-sdk compiles the SDK's C++ headers; libdrd links libusb), which the tests build
# as a lab does; R and its packages recompute the statistics' reference values (tests/r/).
R_PACKAGES := afex lme4 lmerTest ordinal car effectsize coin multcompView
R_CHECK := quit(status = !all(sapply(strsplit("$(R_PACKAGES)", " ")[[1]], requireNamespace, quietly = TRUE)))
system-deps:
	@if ! command -v Xvfb >/dev/null 2>&1 || ! ldconfig -p | grep -q libportaudio \
	    || ! command -v xdotool >/dev/null 2>&1 || ! command -v tmux >/dev/null 2>&1 \
	    || ! command -v strace >/dev/null 2>&1 \
	    || ! command -v chromium >/dev/null 2>&1 || ! command -v cc >/dev/null 2>&1 \
	    || ! command -v arm-none-eabi-gcc >/dev/null 2>&1 \
	    || ! command -v qemu-system-arm >/dev/null 2>&1 \
	    || ! command -v clang-14 >/dev/null 2>&1 || ! dpkg -s libfuzzer-14-dev >/dev/null 2>&1 \
	    || ! command -v g++ >/dev/null 2>&1 || ! dpkg -s libusb-1.0-0-dev >/dev/null 2>&1 \
	    || [ ! -d /usr/lib/arm-none-eabi/newlib ] \
	    || [ ! -f /usr/share/fonts/truetype/dejavu/DejaVuSansMono.ttf ] \
	    || ! dpkg -s libxcb-icccm4 libxcb-keysyms1 libxcb-cursor0 >/dev/null 2>&1 \
	    || ! dpkg -s python3-wxgtk4.0 python3-wxgtk-webview4.0 >/dev/null 2>&1; then \
	  echo "installing Xvfb, Mesa GL, PortAudio, libsndfile, xdotool, tmux, fonts, Qt's X libraries, chromium, the compilers, QEMU, libFuzzer, strace and wxPython (PsychoPy's Builder) from Debian's packages"; \
	  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
	    xvfb libgl1-mesa-dri libglu1-mesa libportaudio2 libasound2 libsndfile1 xdotool tmux \
	    fonts-dejavu-core libxcb-icccm4 libxcb-keysyms1 libxcb-cursor0 libxkbcommon-x11-0 \
	    libxcb-image0 libxcb-render-util0 libxcb-shape0 libxcb-xinerama0 libxcb-xkb1 \
	    chromium gcc libc6-dev make gcc-arm-none-eabi libnewlib-arm-none-eabi \
	    qemu-system-arm clang-14 libfuzzer-14-dev libclang-rt-14-dev strace \
	    g++ libusb-1.0-0-dev python3-wxgtk4.0 python3-wxgtk-webview4.0 >/dev/null; \
	fi
	@if ! command -v Rscript >/dev/null 2>&1 || ! Rscript -e '$(R_CHECK)' >/dev/null 2>&1; then \
	  echo "installing R and the reference packages (afex, lme4, lmerTest, ordinal, car, effectsize, coin, multcompView) from Debian's packages"; \
	  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
	    --no-install-recommends r-base-core r-cran-afex r-cran-lme4 r-cran-lmertest \
	    r-cran-ordinal r-cran-car r-cran-effectsize r-cran-coin r-cran-multcompview >/dev/null; \
	fi

demo: $(STAMP)
	$(VENV)/bin/hapticlab demo

lint: $(STAMP)
	$(VENV)/bin/ruff check .

# The unit tier (tests/tiers.py): in-process tests, no child process, no window, none over a few
# seconds: the inner loop's check, in a few minutes. `make test` is the whole gate CI runs.
check: $(STAMP)
	$(PY) -m pytest -q -m unit

# The native link (device/serial/_hostlink*.so) is built in the source tree: a `git clean -x`
# removes it while the environment's stamp stays, and the suite would then test the Python
# threads' fallback, which a busy computer starves. Rebuild it rather than test without it.
# Two pytest workers by default (pytest-xdist, --dist loadgroup): the real-time tests in one
# group, given out first, and the other worker yields its core to them (tests/conftest.py).
# They pass beside two CPU-bound processes (docs/howto/run-the-tests.md has the runs).
# WORKERS=1 runs one process, about 33-36 minutes where two take about 20.
WORKERS ?= 2
PYTEST_WORKERS := $(if $(filter-out 1,$(WORKERS)),-n $(WORKERS) --dist loadgroup,)
# more of pytest's options for `make test`, such as PYTEST_ARGS=--junitxml=report.xml
PYTEST_ARGS ?=
# the project's own bytecode, compiled before the tests: where PYTHONDONTWRITEBYTECODE is set
# nothing is compiled on import, and each of the suite's hundreds of `python -m app`
# processes compiled what it imports again (0.15 s of a 1.5-s dry-run session)
PACKAGES := app device analysis protocols benchmarks plugins
# the documentation's build runs beside the tests at a lower priority (nothing in the suite
# reads it), its output shown after theirs; either failing fails the gate
DOCS_LOG := $(VENV)/docs.log
test: system-deps
	$(MAKE) -j2 --output-sync=target lint firmware-test
	@$(PY) -c 'import sys; from device.serial.native import load; sys.exit(load()[0] is None)' \
	  || $(PY) -m pip install --quiet --no-deps -e .
	@$(PY) -m compileall -q $(PACKAGES)
	@nice -n 10 $(MAKE) --no-print-directory docs > $(DOCS_LOG) 2>&1 & docs=$$!; \
	  echo "$(PY) -m pytest -q --durations=15 $(PYTEST_WORKERS) $(PYTEST_ARGS)"; \
	  $(PY) -m pytest -q --durations=15 $(PYTEST_WORKERS) $(PYTEST_ARGS); tests=$$?; \
	  wait $$docs; built=$$?; cat $(DOCS_LOG); \
	  if [ $$built -ne 0 ]; then echo "make docs failed (above)"; fi; \
	  exit $$(( tests ? tests : built ))

# the firmware's own tests (firmware/README.md): in `make test`, beside the environment's
# install and then the lint, which needs it (the firmware needs only the compilers; its
# builds and its fuzz run take two cores, the install one or two)
firmware-test:
	$(MAKE) -C firmware test

# The documentation site (docs/, Sphinx + MyST) into docs/_build/html: warnings are errors and
# every cross-reference must resolve (-n), so a broken link or a stale name fails the build.
# -E reads every page afresh: an incremental build would not repeat an unchanged page's
# warnings. No linkcheck: the machines that build it reach no network beyond the registries.
docs: $(STAMP)
	$(PY) -m sphinx -E -W --keep-going -n -q -b html docs docs/_build/html

# The wire contract (device/serial/contract.py) into the files made from it: the firmware's
# include/hl_contract.h and the tables of docs/wire-protocol.md, then the test vectors
contract: $(STAMP)
	$(PY) -m device.serial.contract
	$(PY) -m device.serial.vectors > docs/wire-vectors.txt

# The documentation's screenshots (docs/screens/: the first-session tutorial and the sessions
# reference show them), from the last `make test` (look at them before committing).
SCREENS := realism-instructions realism-tap realism-rating factorial-rating factorial-tap \
           factorial-tap-1920x1080 identification-choose identification-answer debrief pause \
           between-trials-session reference-requested reference-block estop-pause \
           info-dialog operator-view operator-end report-first-screen report-realism \
           threshold-question
screens:
	@mkdir -p docs/screens
	@for s in $(SCREENS); do cp tests/artifacts/screens/$$s.png docs/screens/ || exit 1; done
	@echo "copied $(words $(SCREENS)) screenshots to docs/screens/"

clean:
	rm -rf $(VENV) out .pytest_cache .hypothesis
