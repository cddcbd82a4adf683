# Two commands do everything on a fresh machine that has python3 and make:
#   make run    set up .venv, then reproduce the paper (figures, runs, summaries) into out/;
#               after a kill, make run again continues where it stopped
#   make test   set up .venv, then run the test suite
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp
OUT    ?= out
# make test's pytest workers: one per core, at most 4 (each is a Taichi process of ~1-2 GB)
JOBS   ?= $(shell n=$$(nproc 2>/dev/null || echo 2); [ $$n -gt 4 ] && n=4; echo $$n)

.PHONY: run test test-vulkan vulkan-device validate lint bench docs clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test,sweep]'
	touch $(STAMP)

# A reproduction stopped part-way (a ledger, no summary yet) continues where it stopped
# (--resume); otherwise it starts anew (--overwrite).
run: $(STAMP)
	$(BIN)/taichi-ice paper --out $(OUT)/paper $$(if [ -f $(OUT)/paper/paper-state.json ] \
	  && [ ! -f $(OUT)/paper/summary.json ]; then echo --resume; else echo --overwrite; fi)

validate: $(STAMP)
	$(BIN)/taichi-ice validate --dem --out $(OUT)/validation

# The CPU suite (a worker per core: tests/conftest.py); then one line on the Vulkan lane (`make test-vulkan`), which needs a Vulkan
# device (lavapipe, Mesa's software driver, counts: `apt-get install mesa-vulkan-drivers`).
# The lane took 27 min on the 2-core VM on 2026-11-28 (docs/performance.md): .ci/run runs both.
test: $(STAMP)
	$(BIN)/python -m pytest -q -n $(JOBS) --dist loadfile
	@if $(BIN)/python tests/gpu_lane.py --check; then echo "Vulkan device found: make test-vulkan runs the GPU lane (CI runs it)"; \
	else echo "Vulkan lane skipped: no Vulkan device here (apt-get install mesa-vulkan-drivers gives a software one; then make test-vulkan)"; fi

# Exit 0 when Taichi finds a Vulkan device here (.ci/run asks before the lane).
vulkan-device: $(STAMP)
	@$(BIN)/python tests/gpu_lane.py --check

# The GPU code paths on Vulkan (a kernel per stage; a thread per world), float64 and
# float32: the physics tests that cover every kernel, and the same worlds against the CPU
# (tests/test_gpu.py), a pytest worker per core; the tests marked long_run are left to the
# CPU suite (tests/gpu_lane.py --run vulkan --full runs them too). The list is tests/gpu_lane.py's.
test-vulkan: $(STAMP)
	$(BIN)/python tests/gpu_lane.py --run vulkan

lint: $(STAMP)
	$(BIN)/ruff check taichi_ice tests validation benchmarks
	$(BIN)/ruff format --check taichi_ice tests validation benchmarks

# The documentation site into site/ (open site/index.html), every warning an error: a broken
# link, anchor or snippet, a page left out of the nav, a docstring the reference cannot read.
# tests/test_docs.py builds it the same way in make test.
DOCS_STAMP := $(VENV)/.docs-stamp
$(DOCS_STAMP): $(STAMP)
	$(BIN)/python -m pip install --quiet -e '.[docs]'
	touch $(DOCS_STAMP)

docs: $(DOCS_STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict

bench: $(STAMP)
	$(BIN)/taichi-ice bench --out $(OUT)/bench

clean:
	rm -rf $(VENV) $(OUT) *.egg-info
