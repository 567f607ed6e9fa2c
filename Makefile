# Two commands do everything on a fresh Debian/Ubuntu machine:
#   make run   - install what is missing, then open the application on the example vessel
#   make test  - install what is missing, then run the whole test suite
# Both are idempotent and quick when nothing is missing.

SHELL := /bin/bash
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
VPY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)

# Debian packages: Qt (xcb platform, EGL/GL), VTK (GL, X), virtual screen, LinuxCNC's rs274.
APT_PKGS := libgl1 libegl1 libglu1-mesa libgl1-mesa-dri libosmesa6 libxkbcommon0 libxkbcommon-x11-0 \
  libfontconfig1 libdbus-1-3 libxrender1 libxi6 libxcb-cursor0 libxcb-icccm4 libxcb-image0 \
  libxcb-keysyms1 libxcb-randr0 libxcb-render-util0 libxcb-shape0 libxcb-xinerama0 libxcb-xfixes0 \
  libxcb-xkb1 xvfb xauth x11-utils linuxcnc-uspace python3-venv gcc python3-dev

EXAMPLE := resources/examples/pressure_vessel.toml
# the engine's kernels compiled ahead of time (engine/aot.py): rebuilt when their source changes
AOT := engine/_aot_kernels$(shell $(PYTHON) -c 'import sysconfig; print(sysconfig.get_config_var("EXT_SUFFIX"))')

.PHONY: run test sysdeps venv lint bench clean installer installer-test

run: sysdeps venv $(AOT)
	$(VENV)/bin/winder $(EXAMPLE)

test: sysdeps venv $(AOT)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/lint-imports
	QT_QPA_PLATFORM=offscreen $(VPY) -m pytest -m "not gl" -p no:cacheprovider
	QT_QPA_PLATFORM=xcb xvfb-run -a -s "-screen 0 1600x1000x24" $(VPY) -m pytest -m gl -p no:cacheprovider; \
	  rc=$$?; [ $$rc -eq 0 ] || [ $$rc -eq 5 ]

sysdeps:
	@missing=$$(for p in $(APT_PKGS); do dpkg-query -W -f='$${Status}' $$p 2>/dev/null | grep -q "ok installed" || echo $$p; done); \
	if [ -n "$$missing" ]; then \
	  echo "Installing Debian packages:" $$missing; \
	  $(SUDO) apt-get update -qq && \
	  $(SUDO) env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $$missing; \
	fi

venv: $(STAMP)

$(STAMP): pyproject.toml
	@[ -x $(VPY) ] || $(PYTHON) -m venv $(VENV)
	$(VPY) -m pip install -q --upgrade pip
	$(VPY) -m pip install -q -e ".[test,bench]"
	@# compile the time law's numba kernels into their on-disk cache now (the GUI's threads use them: they
	@# release the GIL; a one-shot run uses the ahead-of-time module below): the first run would pay ~7 s
	$(VPY) -c "from engine.timeparam_jit import warm; warm()"
	touch $(STAMP)

# (not fatal: without the module the numba or numpy code runs, the same answers, slower; the tests say so)
$(AOT): engine/aot.py engine/timeparam_jit.py engine/mandrel_jit.py engine/payout_jit.py engine/winding_jit.py engine/nearest_jit.py engine/numtext_jit.py $(STAMP)
	-$(VPY) -m engine.aot --quiet

lint: venv
	$(VENV)/bin/ruff check .
	$(VENV)/bin/lint-imports

bench: venv $(AOT)
	@for b in benchmarks/bench_*.py; do echo "== $$b"; QT_QPA_PLATFORM=offscreen $(VPY) $$b || exit 1; done

# Frozen one-folder build: dist/winder/ + dist/winder-<version>-linux-x86_64.tar.gz (see installer/README.md).
installer: sysdeps venv $(AOT)
	$(VPY) -m pip install -q -e ".[installer]"
	$(VPY) installer/build.py

# Rebuild only if the sources changed since the last build, then compare the build with the source install.
installer-test: sysdeps venv $(AOT)
	$(VPY) -m pip install -q -e ".[installer]"
	$(VPY) installer/build.py --if-stale
	$(VPY) installer/smoke_test.py

clean:
	rm -rf build dist .pytest_cache .ruff_cache $(AOT)
