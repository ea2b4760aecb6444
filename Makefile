# Two entry points: `make demo` (end to end on the default platform) and `make test`.
# `make cpp`: the C++ feed-forward library (cpp/), its tests, benchmark and example in build/cpp.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
CPP_BUILD := build/cpp
JOBS ?= $(shell nproc 2>/dev/null || echo 2)
# setuptools calls the [tool.setuptools.ext-modules] table of pyproject.toml experimental at every build
EXPERIMENTAL := 'ignore:`[tool.setuptools.ext-modules]`'
# sources of the optional extension agvdyn.ffcpp._core that `pip install -e` builds with CMake
EXTENSION_SOURCES := cpp/CMakeLists.txt src/agvdyn/_ffbuild.py $(wildcard cpp/src/* cpp/include/agvdyn_ff/* cpp/python/*)
# The kernels compiled ahead of time (agvdyn._aot_kernels, by numba.pycc): a command then does not import
# numba (0.3-0.4 s per process). Rebuilt when a kernel source changes; without it (no C compiler) the
# kernels run on numba's JIT, with the same results.
AOT_INDEX := src/agvdyn/_aot_kernels.json
KERNEL_SOURCES := $(shell grep -rl --include='*.py' njit src/agvdyn)

# The second floating-point environment of `make test`: OpenBLAS's generic Prescott kernels instead of
# the CPU's own, numba compiled for a generic x86-64 instead of the host CPU (other rounding, other
# optimiser paths); the tests marked `numerics` must pass under both.
FP_ENV2 ?= OPENBLAS_CORETYPE=Prescott NUMBA_CPU_NAME=generic

.PHONY: demo test bench clean cpp browser

$(STAMP): pyproject.toml $(EXTENSION_SOURCES)
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	PYTHONWARNINGS=$(EXPERIMENTAL) $(BIN)/pip install --quiet -e ".[test]"
	touch $(STAMP)

$(AOT_INDEX): $(STAMP) $(KERNEL_SOURCES)
	$(BIN)/python -m agvdyn._aot_build --quiet || echo "agvdyn: kernels not compiled ahead of time (see above); numba's JIT runs them"

demo: $(STAMP) $(AOT_INDEX)
	$(BIN)/python -m agvdyn.demo

# cpp first: on a fresh machine it installs the compiler that the extension of the install needs
test: cpp browser $(STAMP)
	$(BIN)/python -c "import agvdyn.ffcpp._core" 2>/dev/null || AGVDYN_REQUIRE_CPP=1 PYTHONWARNINGS=$(EXPERIMENTAL) $(BIN)/pip install --quiet --no-deps -e .
	$(MAKE) --no-print-directory $(AOT_INDEX)
	AGVDYN_REQUIRE_CPP=1 AGVDYN_REQUIRE_AOT=1 $(BIN)/python -m pytest -q -n 2
	@echo "numerically sensitive tests (-m numerics) again under a second floating-point environment: $(FP_ENV2)"
	$(FP_ENV2) AGVDYN_REQUIRE_CPP=1 $(BIN)/python -m pytest -q -n 2 -m numerics -p no:cacheprovider

# Headless Chromium for the report's browser test (tests/test_report_browser.py): installed with apt-get
# when missing and running as root; otherwise nothing happens here and that test skips, saying why.
browser:
	@command -v chromium >/dev/null 2>&1 || command -v chromium-browser >/dev/null 2>&1 || \
	command -v google-chrome >/dev/null 2>&1 || { [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1 && \
	(apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null) || true; }

# Checks (and as root on Debian/Ubuntu installs) cmake, g++, Eigen, GoogleTest; configures, builds, runs ctest.
cpp:
	sh cpp/tools/check_deps.sh
	cmake -S cpp -B $(CPP_BUILD) $(if $(wildcard $(CPP_BUILD)/CMakeCache.txt),,$(if $(shell command -v ninja 2>/dev/null),-G Ninja)) -DCMAKE_BUILD_TYPE=Release
	cmake --build $(CPP_BUILD) --parallel $(JOBS)
	cd $(CPP_BUILD) && ctest --output-on-failure

bench: $(STAMP)
	for f in benchmarks/bench_*.py; do $(BIN)/python $$f || exit 1; done
	if [ -x $(CPP_BUILD)/ff_bench ]; then $(CPP_BUILD)/ff_bench; else echo "ff_bench: run make cpp first"; fi

clean:
	rm -rf $(VENV) build demo_output $(AOT_INDEX) src/agvdyn/_aot_kernels*.so
