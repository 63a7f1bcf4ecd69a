# SPDX-License-Identifier: BSD-3-Clause
# imucal: the two commands of the quick start are `make demo` and `make test`.
# Build trees: build/release (demo, benchmarks), build/test (sanitizers, the test suite) and
# build/package (the Debian package, make package).

JOBS ?= $(shell nproc)
CMAKE_GEN := -G Ninja
RELEASE_DIR := build/release
TEST_DIR := build/test
PACKAGE_DIR := build/package
FORMAT_FILES = $(shell git ls-files '*.cpp' '*.hpp' 2>/dev/null)

.PHONY: all deps test-deps build demo test hostile bench package format format-check clean

all: build

deps:
	@scripts/install-deps.sh

test-deps:
	@scripts/install-deps.sh --test

$(RELEASE_DIR)/build.ninja:
	cmake -S . -B $(RELEASE_DIR) $(CMAKE_GEN) -DCMAKE_BUILD_TYPE=Release -DIMUCAL_BUILD_TESTS=OFF

build: deps $(RELEASE_DIR)/build.ninja
	cmake --build $(RELEASE_DIR) -j $(JOBS)

# Runs the main job on the built-in simulated rig (see scripts/demo.sh). The installation of
# missing packages and the build write their output to $(DEMO_LOG); a failure shows its end.
DEMO_LOG := build/demo-build.log
demo:
	@mkdir -p build
	@echo "make demo: installing what is missing and building $(RELEASE_DIR) (a first build takes 15 min or more on 2 cores); output in $(DEMO_LOG)"
	@$(MAKE) --no-print-directory build >$(DEMO_LOG) 2>&1 || { tail -n 30 $(DEMO_LOG); \
	  echo "make demo: installing or building failed; the whole output is in $(DEMO_LOG)"; exit 1; }
	@scripts/demo.sh $(RELEASE_DIR)

$(TEST_DIR)/build.ninja:
	cmake -S . -B $(TEST_DIR) $(CMAKE_GEN) -DCMAKE_BUILD_TYPE=RelWithDebInfo \
	  -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1" -DIMUCAL_SANITIZE=ON -DIMUCAL_WERROR=ON \
	  -DIMUCAL_UNITY_TESTS=ON

# Builds with AddressSanitizer + UndefinedBehaviorSanitizer and runs every test through ctest.
test: test-deps format-check $(TEST_DIR)/build.ninja
	cmake --build $(TEST_DIR) -j $(JOBS)
	ctest --test-dir $(TEST_DIR) --output-on-failure -j $(JOBS) --timeout 900

# The hostile cases of docs/hostile-inputs.md alone (tests/hostile-cases.txt), in the test build.
HOSTILE_TESTS = $(shell sed -e 's/\#.*//' -e 's/[[:space:]]//g' -e '/^$$/d' tests/hostile-cases.txt | paste -sd'|')
hostile: test-deps $(TEST_DIR)/build.ninja
	cmake --build $(TEST_DIR) -j $(JOBS)
	ctest --test-dir $(TEST_DIR) --output-on-failure -j $(JOBS) --timeout 900 -R '^($(HOSTILE_TESTS)|hostile.cases_listed)$$'

bench: deps
	cmake -S . -B build/bench $(CMAKE_GEN) -DCMAKE_BUILD_TYPE=Release -DIMUCAL_BUILD_TESTS=ON
	cmake --build build/bench -j $(JOBS)
	scripts/bench.sh build/bench

# Release, tests off, prefix /usr, with the hardening Debian builds with (fortified functions,
# immediate binding), which lintian checks.
$(PACKAGE_DIR)/build.ninja:
	cmake -S . -B $(PACKAGE_DIR) $(CMAKE_GEN) -DCMAKE_BUILD_TYPE=Release -DIMUCAL_BUILD_TESTS=OFF \
	  -DIMUCAL_BUILD_BENCH=OFF -DCMAKE_INSTALL_PREFIX=/usr -DCMAKE_CXX_FLAGS=-D_FORTIFY_SOURCE=2 \
	  -DCMAKE_EXE_LINKER_FLAGS=-Wl,-z,now -DCMAKE_MODULE_LINKER_FLAGS=-Wl,-z,now \
	  -DCMAKE_SHARED_LINKER_FLAGS=-Wl,-z,now

# The Debian packages $(PACKAGE_DIR)/imucal_VERSION_ARCH.deb and the camera backends'
# imucal-aravis_ and imucal-libcamera_ (CPack; docs/service.md).
package: deps $(PACKAGE_DIR)/build.ninja
	cmake --build $(PACKAGE_DIR) -j $(JOBS)
	cmake --build $(PACKAGE_DIR) --target package
	@ls -l $(PACKAGE_DIR)/imucal*.deb

format:
	clang-format -i $(FORMAT_FILES)

format-check:
	@clang-format --dry-run --Werror $(FORMAT_FILES) && echo "format-check: OK"

clean:
	rm -rf build
