# Two commands do everything on a fresh machine that has python3 and make:
#   make run    set up .venv, then reproduce the paper (figures, runs, summaries) into out/;
#               after a kill, make run again continues where it stopped
#   make test   set up .venv, then run the test suite
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp
OUT    ?= out

.PHONY: run test validate lint bench clean

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

test: $(STAMP)
	$(BIN)/python -m pytest -q

lint: $(STAMP)
	$(BIN)/ruff check taichi_ice tests validation benchmarks
	$(BIN)/ruff format --check taichi_ice tests validation benchmarks

bench: $(STAMP)
	$(BIN)/taichi-ice bench --out $(OUT)/bench

clean:
	rm -rf $(VENV) $(OUT) *.egg-info
