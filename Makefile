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

# What accuracy costs: CSV files and plots for the bundled scenes, in docs/accuracy/.
accuracy: setup
	$(PY) -m tracer bench accuracy scenes/lecture.sdl scenes/glass.sdl scenes/shapes.sdl scenes/textures.sdl \
		--width 320 --height 240 -o docs/accuracy

# Benchmarks (bench/run.py): whole-process time against POV-Ray 3.7 at 1280x960 on 2 threads, scaling from
# 10 to 10,000 spheres, and the C core against the NumPy path. Needs povray (apt-get install -y povray) and,
# for the plot in docs/performance.png, matplotlib; results go to bench/results/results.json. bench/memory.py:
# peak memory of 960x540 to 4K renders in full-frame buffers (bench/results/memory.json). bench/scale.py:
# 1e4..1e6 triangles and 1e3..1e6 spheres against POV-Ray, time and peak memory, the read/build/trace/write
# split and Embree's primary-ray rate (bench/results/scale.json, docs/performance-scale.png; tens of minutes).
.PHONY: bench
bench: setup
	$(PY) bench/run.py
	$(PY) bench/memory.py
	$(PY) bench/scale.py

# The Blender extension zip (Blender 4.2+) and the legacy add-on zip (Blender 3.x/4.1), in dist/.
.PHONY: extension
extension: setup
	$(PY) scripts/build_extension.py
	$(PY) scripts/build_extension.py --legacy
