# lmrefine: `make demo` and `make test` work on a fresh Debian 12 machine as
# root: they install the Debian packages they need, configure and build.

PYTHON    ?= /usr/bin/python3
BUILD_DIR ?= build
ASAN_DIR  ?= build-asan
JOBS      ?= $(shell nproc)
DEMO_OUT  ?= demo_out

# Everything comes from Debian 12 packages.
DEBIAN_PACKAGES := cmake g++ clang make pkg-config pybind11-dev libembree-dev libtbb-dev \
	libopenimageio-dev libglm-dev libeigen3-dev python3-dev python3-numpy python3-pytest \
	python3-pywt python3-matplotlib python3-distributed blender

.PHONY: all deps build install test test-asan check-compilers fuzz bench demo evaluate samples sample-lightmap addon-zip clean

all: build

# Installs only what is missing, so repeated runs cost a dpkg query.
deps:
	@missing=$$(for p in $(DEBIAN_PACKAGES); do \
		dpkg-query -W -f='$${Status}\n' $$p 2>/dev/null | grep -q '^install ok installed' || echo $$p; done); \
	if [ -n "$$missing" ]; then \
		echo "Installing Debian packages:" $$missing; \
		if [ "$$(id -u)" != 0 ]; then echo "error: run as root (or install: $$missing)"; exit 1; fi; \
		apt-get update -q && DEBIAN_FRONTEND=noninteractive apt-get install -y -q $$missing; \
	fi

$(BUILD_DIR)/CMakeCache.txt: | deps
	cmake -S . -B $(BUILD_DIR) -DCMAKE_BUILD_TYPE=Release -DPython_EXECUTABLE=$(PYTHON)

build: deps $(BUILD_DIR)/CMakeCache.txt
	cmake --build $(BUILD_DIR) -j $(JOBS)

install: build
	cmake --install $(BUILD_DIR)

# Every test against the release build and, side by side with them, the
# native ones again under the sanitizers (a memory error in the core fails
# CI, not a user's scene). The release tests keep about one core busy, so the
# sanitized build and its tests take the other: 6 minutes less on 2 cores
# than one after the other (docs/history.md). The sanitizer side writes
# $(ASAN_LOG), printed when both have finished; either failing fails the target.
ASAN_LOG := $(ASAN_DIR).log
test: build check-compilers
	@echo "make test-asan runs beside these tests; its output ($(ASAN_LOG)) follows them"
	@$(MAKE) --no-print-directory test-asan > $(ASAN_LOG) 2>&1 & asan=$$!; \
	PYTHONPATH=python $(PYTHON) -m pytest tests -q; release=$$?; \
	echo "== waiting for make test-asan ($(ASAN_LOG))"; \
	wait $$asan; sanitized=$$?; cat $(ASAN_LOG); \
	echo "== release tests: exit $$release; make test-asan: exit $$sanitized"; \
	[ $$release -eq 0 ] && [ $$sanitized -eq 0 ]

# Every native source compiled (front end only, about a minute) with clang
# as portable C++17: -Wpedantic -Werror, so a warning or a language extension
# fails the test. gcc gets the same check in test-asan's build, which
# compiles every source with these warnings and -Werror. The release build is gcc.
CHECK_CXXFLAGS := -fsyntax-only -std=c++17 -Wall -Wextra -Wno-unused-parameter -Wpedantic -Werror -fvisibility=hidden \
	-Inative/include -Inative/src -isystem /usr/include/eigen3 -DLMREFINE_VERSION='"check"'
check-compilers: deps
	@echo "clang++: $$(clang++ --version | head -1)"
	@find native/src native/bindings -name '*.cpp' | sort | xargs -P $(JOBS) -n 4 \
		clang++ $(CHECK_CXXFLAGS) $$(python3-config --includes)

# The native tests under AddressSanitizer + UndefinedBehaviorSanitizer. The
# sanitized module is built into its own folder so it never replaces the
# release one; libasan (and libstdc++, so its throw interceptor finds the
# real __cxa_throw) must be preloaded into the (unsanitized) Python. A failed
# allocation returns null as in a release build (numpy then raises
# MemoryError) instead of aborting. -O1 with line tables only (-g1) compiles
# in half the time of -O2 -g and still gives the sanitizers' reports file:line.
ASAN_OPT_FLAGS := -O1 -g1 -DNDEBUG
test-asan: deps
	cmake -S . -B $(ASAN_DIR) -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="$(ASAN_OPT_FLAGS)" \
		-DLMREFINE_SANITIZE=ON -DLMREFINE_WERROR=ON \
		-DPython_EXECUTABLE=$(PYTHON) -DLMREFINE_MODULE_DIR=$(CURDIR)/$(ASAN_DIR)/package/lmrefine
	cmake --build $(ASAN_DIR) -j $(JOBS)
	tar -C python --exclude="_native*.so" --exclude=__pycache__ -cf - lmrefine | tar -C $(ASAN_DIR)/package -xf -
	ln -sfn $(CURDIR)/blend_samples $(ASAN_DIR)/blend_samples
	LD_PRELOAD="$$($(CXX) -print-file-name=libasan.so) $$($(CXX) -print-file-name=libstdc++.so)" ASAN_OPTIONS=detect_leaks=0:allocator_may_return_null=1 \
		UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 LMREFINE_PYTHONPATH=$(ASAN_DIR)/package \
		$(PYTHON) -m pytest tests -q -m "not blender and not slow" -p no:cacheprovider

# The fuzz suite (tests/fuzz, docs/robustness.md): FUZZ_CASES hostile calls of
# the Python API, each in a forked child with a timeout, then FUZZ_BLENDER_CASES
# runs of the add-on's operator on broken meshes in one headless Blender.
# Prints the outcome counts; fails on any crash, hang, unpromised exception,
# invalid layout or modified input. FUZZ_SEED=n repeats a run.
FUZZ_CASES         ?= 10000
FUZZ_BLENDER_CASES ?= 300
fuzz: build
	$(PYTHON) tests/fuzz/run.py --cases $(FUZZ_CASES) --blender-cases $(FUZZ_BLENDER_CASES) \
		$(if $(FUZZ_SEED),--seed $(FUZZ_SEED))

bench: build
	PYTHONPATH=python $(PYTHON) bench/run.py

# The whole pipeline on the bundled courtyard at 256^2: bake, refine, re-bake,
# measure; prints the summary table, writes $(DEMO_OUT)/report.md + pictures.
demo: build
	PYTHONPATH=python $(PYTHON) -m lmrefine demo --out $(DEMO_OUT)

# Every bundled sample scene with its Smart UV Project layout at 256^2.
evaluate: build
	PYTHONPATH=python $(PYTHON) -m lmrefine evaluate --out evaluate_out

# Rebuild the sample scenes (blend_samples/*.blend and their .npz) in Blender;
# `make samples SCENES=atrium` rebuilds only the scenes named.
samples:
	blender -b --factory-startup --python-exit-code 1 \
		--python blend_samples/make_samples.py -- blend_samples $(SCENES)

# The Blender add-on as one installable zip: the add-on, the lmrefine package
# and its compiled extension (docs/blender.md).
addon-zip: build
	$(PYTHON) addon/build_zip.py --out dist/lmrefine_blender.zip

clean:
	rm -rf $(BUILD_DIR) $(ASAN_DIR) $(ASAN_LOG) $(DEMO_OUT) evaluate_out dist python/lmrefine/_native*.so

# Re-bake the bundled sample lightmap and its layout with Cycles.
sample-lightmap: build
	PYTHONPATH=$(CURDIR)/python blender -b --factory-startup --python-exit-code 1 \
		--python blend_samples/make_sample_lightmap.py -- blend_samples 256
