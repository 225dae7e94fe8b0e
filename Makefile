# Quick start:  make demo   (sets up .venv, renders scenes/lecture.sdl to out/lecture.png)
#               make test   (sets up if needed, runs the whole suite)
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: setup demo test clean accuracy

setup: $(STAMP)

$(STAMP): pyproject.toml requirements-dev.txt
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -r requirements-dev.txt
	$(PY) -m pip install -q --no-deps -e .
	touch $(STAMP)

demo: setup
	mkdir -p out
	$(PY) -m tracer render scenes/lecture.sdl -o out/lecture.png --width 640 --height 480 --stats

test: setup
	$(PY) -m pytest -q

clean:
	rm -rf $(VENV) out build *.egg-info

# What accuracy costs: CSV, JSON, plots and report.md for the bundled scenes, in docs/accuracy/ (96 x 72,
# a 2,048-ray reference, 5 seeds per setting: about 10 minutes of 2 cores; see docs/accuracy.md).
accuracy: setup
	$(PY) -m tracer bench accuracy scenes/lecture.sdl scenes/glass.sdl scenes/shapes.sdl scenes/textures.sdl \
		-o docs/accuracy

# Benchmarks (bench/run.py): whole-process time against POV-Ray 3.7 at 1280x960 on 2 threads, scaling from
# 10 to 10,000 spheres, and the C core against the NumPy path. Needs povray (apt-get install -y povray) and,
# for the plot in docs/performance.png, matplotlib; results go to bench/results/results.json. bench/memory.py:
# peak memory of 960x540 to 4K renders in full-frame buffers (bench/results/memory.json). bench/scale.py:
# 1e4..1e6 triangles and 1e3..1e6 spheres against POV-Ray, time and peak memory, the read/build/trace/write
# split and Embree's primary-ray rate (bench/results/scale.json, docs/performance-scale.png; tens of minutes).
# bench/sdl_read.py: reading SDL files of 1e4..1e6 spheres, seconds and bytes per shape (bench/results/
# sdl_read.json; --against DIR times another checkout in turn with this one).
# Rendering on a Dask cluster (bench/cluster.py): the 4K glass.sdl table of docs/distributed.md, plain local
# against --scheduler local:1 and local:2, and the per-tile overhead (bench/results/distributed.json).
.PHONY: bench-cluster
bench-cluster: setup
	$(PY) bench/cluster.py

.PHONY: bench
bench: setup
	$(PY) bench/run.py
	$(PY) bench/memory.py
	$(PY) bench/scale.py
	$(PY) bench/sdl_read.py

# The Blender extension zips in dist/: linux-x64 and windows-x64 with the C core prebuilt (Windows
# cross-compiled with mingw-w64 and smoke-tested under Wine when installed), one for other platforms
# (macOS: compiled on first use), and the legacy add-on zip for Blender 3.x/4.1. Needs cmake.
.PHONY: extension
extension: setup
	$(PY) scripts/build_extension.py --all

# The C core, built by CMake as the wheel builds it (CMakeLists.txt; needs cmake):
#   make warnings   -Wall -Wextra -Werror with gcc and with clang (apt-get install -y clang)
#   make sanitize   the C-vs-NumPy tests and the fuzz corpus (tests/fuzz; USD cases left out: usd-core aborts
#                   under a preloaded ASan) with the core built under AddressSanitizer and UBSan
#   make wheel      pip wheel . into dist/, then the packaging tests: the wheel and the extension zips
#                   render with the prebuilt core where no compiler is on PATH
CMAKE ?= cmake
SANITIZED := build/sanitize/_core.so
SANITIZE_TESTS := tests/test_native.py tests/test_contract.py tests/test_backend.py tests/test_mesh_intersect.py tests/fuzz \
	tests/test_sdl_fastread.py tests/test_instances.py tests/test_lights.py

.PHONY: warnings sanitize wheel contract
warnings:
	@for cc in gcc clang; do \
		if ! command -v $$cc >/dev/null; then echo "warning: $$cc not found, not checked" >&2; continue; fi; \
		$(CMAKE) -S . -B build/warnings-$$cc -DCMAKE_C_COMPILER=$$cc -DRT_WERROR=ON >/dev/null && \
		$(CMAKE) --build build/warnings-$$cc --clean-first || exit 1; \
	done

sanitize: setup
	$(CMAKE) -S . -B build/sanitize -DCMAKE_C_COMPILER=gcc -DRT_SANITIZE=ON -DRT_WERROR=ON >/dev/null
	$(CMAKE) --build build/sanitize
	SDL_TRACER_LIBRARY=$(CURDIR)/$(SANITIZED) LD_PRELOAD="$$(gcc -print-file-name=libasan.so)" \
		ASAN_OPTIONS=detect_leaks=0:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
		$(PY) -m pytest -q -p no:cacheprovider $(SANITIZE_TESTS)

wheel: setup
	rm -f dist/sdl_raytracer-*.whl
	$(PY) -m pip wheel -q --no-deps -w dist .
	SDL_TRACER_WHEEL="$$(ls dist/sdl_raytracer-*.whl)" $(PY) -m pytest -q -m packaging tests/test_packaging.py

# Rewrites tracer/native/contract.h from tracer/native/contract.py (see docs/contributing.md).
contract: setup
	$(PY) -W ignore::RuntimeWarning -m tracer.native.contract

# Hostile input (tests/fuzz/): 10,000 inputs through the command line, each in its own process: half of them
# mutated scenes, meshes, images and USD stages (mutate.py), half generated (generators.py: deep ray trees,
# extreme mesh and USD numbers, pictures of every format, hostile stages, signals and kills at random moments,
# output names of every length, hits on shared edges, the two SDL readers compared); fails on any traceback,
# signal, hang past 20 s, memory past 2 GB, litter, readers or C != NumPy.  Failing inputs are copied to
# out/fuzz-findings/.  The test suite runs a seeded slice of 300.
.PHONY: fuzz
fuzz: setup
	$(PY) tests/fuzz/fuzz.py --count 10000 --seed $${FUZZ_SEED:-1} --findings out/fuzz-findings
